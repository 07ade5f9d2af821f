/* Compiled kernels of fsdvs_hw/sensor/crossings.py: one comparator step's events and one frame
 * interval's stable time sort, on CPU arrays (built and loaded by _crossings_native.py).
 *
 * The formulas are those of crossings.crossing_step_torch, operation for operation and in the
 * same order. IEEE + - * / are correctly rounded and floor, ceil, fmin/fmax and nextafter exact,
 * so results are bit-identical as long as the compiler neither contracts a*b+c into an FMA nor
 * reassociates: built with -ffp-contract=off and without -ffast-math (x86-64 evaluates float in
 * float, FLT_EVAL_METHOD 0).
 *
 * Crossing times follow ESIM's linear model (Rebecq, Gehrig & Scaramuzza 2018):
 * t = t_a + (j C - d_a) / v for the j-th crossing of a step.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

#define BIG_BUCKET 32

static inline double threshold_f32(const float *c, int64_t n, int64_t i, int64_t hw) {
    if (n == 1) return (double)c[0];
    if (n == hw) return (double)c[i % hw];
    return (double)c[i];
}

static inline double threshold_f64(const double *c, int64_t n, int64_t i, int64_t hw) {
    if (n == 1) return c[0];
    if (n == hw) return c[i % hw];
    return c[i];
}

/* Events of one step in input order (ON pixels first, raster order, each pixel's events
 * consecutive). Arrays are over the n_pix = B*H*W flattened pixels; c_on/c_off hold 1, H*W or
 * B*H*W values; t_a, t_b, dt hold B values. last_t is updated in place when use_refr. em_on/em_off
 * (NULL: not wanted) receive the emitted counts. flat/t/p (NULL unless collecting) need room for
 * every emitted event. Returns the number of events written; *lost receives the crossings lost to
 * the refractory period. */
#define STEP_EVENTS(NAME, REAL, THRESHOLD)                                                          \
    int64_t NAME(const REAL *h_on, const REAL *h_off, const REAL *sig_a, const REAL *ref_a,         \
                 const REAL *d_b, const REAL *c_on, int64_t n_c_on, const REAL *c_off,               \
                 int64_t n_c_off, const double *t_a, const double *t_b, const double *dt,           \
                 int64_t n_pix, int64_t hw, double *last_t, double refr, int use_refr,               \
                 REAL *em_on, REAL *em_off, int32_t *flat, double *t, int8_t *p, double *lost) {    \
        int64_t k = 0;                                                                              \
        double lost_sum = 0.0;                                                                      \
        for (int pol = 0; pol < 2; pol++) {                                                         \
            const REAL *h = pol == 0 ? h_on : h_off;                                                \
            const REAL *c = pol == 0 ? c_on : c_off;                                                \
            int64_t n_c = pol == 0 ? n_c_on : n_c_off;                                              \
            REAL *em = pol == 0 ? em_on : em_off;                                                   \
            int8_t sign = pol == 0 ? 1 : -1;                                                        \
            for (int64_t i = 0; i < n_pix; i++) {                                                   \
                REAL hi = h[i];                                                                     \
                if (!(hi > 0)) continue;                                                            \
                double n = (double)hi;                                                              \
                int64_t b = i / hw;                                                                 \
                REAL da_r = sig_a[i] - ref_a[i];                                                    \
                double da = (double)da_r;                                                           \
                double v = ((double)d_b[i] - da) / dt[b];                                           \
                if (sign < 0) {                                                                     \
                    da = -da;                                                                       \
                    v = -v;                                                                         \
                }                                                                                   \
                double cc = THRESHOLD(c, n_c, i, hw);                                               \
                double ta = t_a[b];                                                                 \
                int rising = v > 0;                                                                 \
                double j0 = 1.0, m = 1.0, emitted;                                                  \
                if (!use_refr) {                                                                    \
                    emitted = rising ? n : 0.0;                                                     \
                } else {                                                                            \
                    double vs = rising ? v : 1.0;                                                   \
                    j0 = ceil((vs * (last_t[i] + refr - ta) + da) / cc);                            \
                    if (!(j0 >= 1.0)) j0 = 1.0;                                                     \
                    m = ceil(refr * vs / cc);                                                       \
                    if (!(m >= 1.0)) m = 1.0;                                                       \
                    emitted = n >= j0 ? 1.0 + floor((n - j0) / m) : 0.0;                            \
                    if (!rising) emitted = 0.0;                                                     \
                    if (emitted > 0) {                                                              \
                        double j_last = j0 + (emitted - 1.0) * m;                                   \
                        last_t[i] = ta + (j_last * cc - da) / vs;                                   \
                    }                                                                               \
                    lost_sum += n - emitted;                                                        \
                }                                                                                   \
                if (em) em[i] = (REAL)emitted;                                                      \
                if (!flat || !(emitted > 0)) continue;                                              \
                double lo = nextafter(ta, INFINITY), hi_t = t_b[b];                                 \
                int64_t ne = (int64_t)emitted;                                                      \
                for (int64_t q = 0; q < ne; q++) {                                                  \
                    double j = (double)q;                                                           \
                    j = use_refr ? j * m + j0 : j + 1.0;                                            \
                    double tt = (j * cc - da) / v + ta;                                             \
                    if (tt < lo) tt = lo;                                                           \
                    if (tt > hi_t) tt = hi_t;                                                       \
                    flat[k] = (int32_t)i;                                                           \
                    t[k] = tt;                                                                      \
                    p[k] = sign;                                                                    \
                    k++;                                                                            \
                }                                                                                   \
            }                                                                                       \
        }                                                                                           \
        *lost = lost_sum;                                                                           \
        return k;                                                                                   \
    }

STEP_EVENTS(fsdvs_step_events_f32, float, threshold_f32)
STEP_EVENTS(fsdvs_step_events_f64, double, threshold_f64)

/* Bucket of a time: floor((t - lo) * scale) clamped into [0, nb - 1]; monotone in t. */
static inline int64_t bucket_of(double tt, double lo, double scale, int64_t nb) {
    double f = (tt - lo) * scale;
    if (!(f > 0)) return 0; /* also NaN */
    if (f >= (double)nb) return nb - 1;
    return (int64_t)f;
}

/* Stable merge sort of the indices in a[0:n] by key t[index] (ties keep their order), using b as
 * scratch; returns whichever of a, b holds the result. */
static const int64_t *merge_sort_idx(int64_t *a, int64_t *b, const double *t, int64_t n) {
    for (int64_t width = 1; width < n; width *= 2) {
        for (int64_t lo = 0; lo < n; lo += 2 * width) {
            int64_t mid = lo + width < n ? lo + width : n;
            int64_t hi = lo + 2 * width < n ? lo + 2 * width : n;
            int64_t i = lo, j = mid, o = lo;
            while (i < mid && j < hi) b[o++] = t[a[j]] < t[a[i]] ? a[j++] : a[i++];
            while (i < mid) b[o++] = a[i++];
            while (j < hi) b[o++] = a[j++];
        }
        int64_t *s = a;
        a = b;
        b = s;
    }
    return a;
}

/* Stable sort by t inside each bucket [starts[b], starts[b + 1]), in place. Returns 0, or -1 when
 * a scratch allocation failed. */
static int sort_buckets(const int32_t *starts, int64_t nb, int32_t *flat, double *t, int8_t *p) {
    for (int64_t b = 0; b < nb; b++) {
        int64_t s = starts[b], e = starts[b + 1], len = e - s;
        if (len < 2) continue;
        if (len > BIG_BUCKET) {
            int64_t *idx = malloc(sizeof(int64_t) * 2 * len);
            double *t2 = malloc(sizeof(double) * len);
            int32_t *f2 = malloc(sizeof(int32_t) * len);
            int8_t *p2 = malloc(len);
            if (!idx || !t2 || !f2 || !p2) {
                free(idx), free(t2), free(f2), free(p2);
                return -1;
            }
            for (int64_t i = 0; i < len; i++) idx[i] = i;
            const int64_t *order = merge_sort_idx(idx, idx + len, t + s, len);
            for (int64_t i = 0; i < len; i++) {
                t2[i] = t[s + order[i]];
                f2[i] = flat[s + order[i]];
                p2[i] = p[s + order[i]];
            }
            for (int64_t i = 0; i < len; i++) {
                t[s + i] = t2[i];
                flat[s + i] = f2[i];
                p[s + i] = p2[i];
            }
            free(idx), free(t2), free(f2), free(p2);
            continue;
        }
        for (int64_t i = s + 1; i < e; i++) {
            double ti = t[i];
            if (!(ti < t[i - 1])) continue;
            int32_t fi = flat[i];
            int8_t pi = p[i];
            int64_t j = i - 1;
            while (j >= s && t[j] > ti) {
                t[j + 1] = t[j];
                flat[j + 1] = flat[j];
                p[j + 1] = p[j];
                j--;
            }
            t[j + 1] = ti;
            flat[j + 1] = fi;
            p[j + 1] = pi;
        }
    }
    return 0;
}

/* Stable sort by time of one frame interval's events, given as n_parts parts (concatenated in
 * order), into flat_out/t_out/p_out: a counting sort into nb buckets (bucket_of is monotone in
 * time, so buckets are ordered), then a stable sort inside each bucket (insertion; merge sort
 * above BIG_BUCKET events). counts: scratch of nb + 1 entries. Returns 0, or -1 when a scratch
 * allocation failed. */
int fsdvs_sort_interval(int64_t n_parts, const int64_t *lens, const int32_t *const *flats,
                        const double *const *ts, const int8_t *const *ps, double lo, double scale, int64_t nb,
                        int32_t *counts, int32_t *flat_out, double *t_out, int8_t *p_out) {
    for (int64_t b = 0; b <= nb; b++) counts[b] = 0;
    for (int64_t q = 0; q < n_parts; q++)
        for (int64_t i = 0; i < lens[q]; i++) counts[bucket_of(ts[q][i], lo, scale, nb) + 1]++;
    for (int64_t b = 0; b < nb; b++) counts[b + 1] += counts[b]; /* counts[b] = first slot of bucket b */
    for (int64_t q = 0; q < n_parts; q++) {
        const int32_t *f = flats[q];
        const double *t = ts[q];
        const int8_t *p = ps[q];
        for (int64_t i = 0; i < lens[q]; i++) {
            int32_t j = counts[bucket_of(t[i], lo, scale, nb)]++;
            flat_out[j] = f[i];
            t_out[j] = t[i];
            p_out[j] = p[i];
        }
    }
    /* now counts[b] = end of bucket b = start of bucket b + 1; shift back to starts */
    for (int64_t b = nb; b > 0; b--) counts[b] = counts[b - 1];
    counts[0] = 0;
    return sort_buckets(counts, nb, flat_out, t_out, p_out);
}

/* One sorted interval into the event columns: y = (f mod hw) / w, x = (f mod hw) - y w. */
void fsdvs_write_columns(const int32_t *flat, const double *t, const int8_t *p, int64_t n, int64_t hw,
                         int64_t w, int64_t *x_out, int64_t *y_out, double *t_out, int8_t *p_out) {
    int32_t hw32 = (int32_t)hw, w32 = (int32_t)w;
    for (int64_t i = 0; i < n; i++) {
        int32_t f = flat[i];
        if (f >= hw32) f %= hw32;
        int32_t yy = f / w32;
        y_out[i] = yy;
        x_out[i] = f - yy * w32;
        t_out[i] = t[i];
        p_out[i] = p[i];
    }
}
