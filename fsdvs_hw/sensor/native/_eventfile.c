/* Compiled kernel of fsdvs_hw/sensor/eventfiles/eventfile.py: one slice of event columns converted to the
 * writer process's message layout and checked, in one pass (built and loaded by
 * library.py).
 *
 * The conversion is NumPy's, operation for operation: t_us = rint(t * 1e6) (IEEE multiply, then
 * rounding to nearest even in the default mode, as np.rint), x and y narrowed to int16, p to
 * 1 (ON) / 0 (OFF). Built with -ffp-contract=off (no FMA).
 */
#include <math.h>
#include <stdint.h>

/* Returns 0, or the first problem found (the caller then finds and words it with NumPy):
 * 1 a time that is negative or not a number, 2 a pixel outside width x height, 3 a polarity
 * other than +1 / -1, 4 a time earlier than the one before it (the first against last_t_us),
 * 5 a time after max_t_us. */
int fsdvs_event_message(const double *t, const int64_t *x, const int64_t *y, const int8_t *p, int64_t n,
                        int64_t width, int64_t height, int64_t last_t_us, int64_t max_t_us, int64_t *t_out,
                        int16_t *x_out, int16_t *y_out, uint8_t *p_out) {
    int64_t prev = last_t_us;
    double top = (double)max_t_us; /* compared in double: no conversion of an out-of-range time */
    for (int64_t i = 0; i < n; i++) {
        double v = rint(t[i] * 1e6);
        if (!(v >= 0.0)) return 1;
        if (v > top) return 5;
        int64_t us = (int64_t)v;
        if (us < prev) return 4;
        prev = us;
        int64_t xi = x[i], yi = y[i];
        if (xi < 0 || xi >= width || yi < 0 || yi >= height) return 2;
        int8_t pi = p[i];
        if (pi != 1 && pi != -1) return 3;
        t_out[i] = us;
        x_out[i] = (int16_t)xi;
        y_out[i] = (int16_t)yi;
        p_out[i] = (uint8_t)(pi > 0);
    }
    return 0;
}
