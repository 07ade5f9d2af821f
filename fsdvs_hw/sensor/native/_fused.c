/* Compiled no-grad CPU paths of fsdvs_hw/sensor/native/fused.py (built and loaded by library.py):
 * one sub-step of the photoreceptor low-pass, the reference leak and the comparator in one pass
 * over the pixels (events._advance_steps); v2e's linear-log response around torch's log
 * (pixel.linlog_v2e); the positivity floor and its count (filtering._FloorSTE).
 *
 * The formulas are those of events._substep_target, pixel.lowpass_step, events._Comparator,
 * pixel.linlog_v2e and filtering._FloorSTE, operation for operation, in the same order and in
 * the same precision (torch evaluates a
 * float32 tensor op with a Python scalar in float32: the scalars arrive here already rounded).
 * IEEE + - * / and floor are correctly rounded, so with -ffp-contract=off and no -ffast-math the
 * results are bit-identical to torch's. The transcendentals stay with torch (its vectorised and
 * scalar lanes differ in the last bit): for the sub-step the caller computes the exponent with
 * lowpass_exponent, applies torch.expm1 in place, and passes it to pixel_step; for the response
 * it applies torch.log between linlog_clamp and linlog_finish.
 * Comparisons are written so that a NaN propagates as in torch.clamp.
 */
#include <math.h>
#include <stddef.h>
#include <stdint.h>

#include "_native_clones.h"

/* x = ((-2 pi) * (f_c * clamp((I + dark) / fs, 0, 1))) * dt[b], per pixel (events._substep_target
 * and pixel.lowpass_step). inten: n_pix = B*hw values; dt: B values. */
#define LOWPASS_EXPONENT(NAME, REAL)                                                                \
    FSDVS_CLONES void NAME(const REAL *inten, int64_t n_pix, int64_t hw, const REAL *dt, REAL dark, REAL fs,     \
              REAL cutoff, REAL m2pi, REAL *x) {                                                    \
        int64_t n_b = hw > 0 ? n_pix / hw : 0;                                                      \
        for (int64_t b = 0; b < n_b; b++) {                                                         \
            REAL dtb = dt[b];                                                                       \
            const REAL *in = inten + b * hw;                                                        \
            REAL *out = x + b * hw;                                                                 \
            for (int64_t r = 0; r < hw; r++) {                                                      \
                REAL a = (in[r] + dark) / fs;                                                       \
                a = a < (REAL)0 ? (REAL)0 : a;                                                      \
                a = a > (REAL)1 ? (REAL)1 : a;                                                      \
                out[r] = (m2pi * (cutoff * a)) * dtb;                                               \
            }                                                                                       \
        }                                                                                           \
    }

LOWPASS_EXPONENT(fsdvs_lowpass_exponent_f32, float)
LOWPASS_EXPONENT(fsdvs_lowpass_exponent_f64, double)

/* One comparator sub-step. target: the interpolated log signal; with em1 (expm1 of the exponent,
 * or NULL without photoreceptor) the low-pass runs first: lp' = lp + (-em1) (target - lp), and lp'
 * is what the comparator sees (written to lp_out). Leak: r = ref - (leak c_on) dt[b] (leak = 0
 * leaves r exactly as it is). Comparator: d = target - r, n_on = floor(max(d, 0) / c_on + eps),
 * n_off = floor(-(min(d, 0) / c_off) + eps), r' = fma(-n_off, c_off, fma(n_on, c_on, r)):
 * torch.addcmul rounds once (it is one fused multiply-add in torch's CPU kernels, vector and
 * scalar lanes alike, float32 and float64, measured). c_on/c_off hold hw values (shared by the
 * batch) or n_pix values. Outputs: ref_out (r'), n_on, n_off, d_out (d). */
#define COMPARATOR(REAL, FLOOR, FMA)                                                                \
    REAL rr = ref[r] - (leak * con[r]) * dtb;                                                       \
    REAL d = tg - rr;                                                                               \
    REAL pos = d < (REAL)0 ? (REAL)0 : d;                                                           \
    REAL neg = d > (REAL)0 ? (REAL)0 : d;                                                           \
    REAL hon = FLOOR(pos / con[r] + eps);                                                           \
    REAL hoff = FLOOR(-(neg / coff[r]) + eps);                                                      \
    ref_out[r] = FMA(-hoff, coff[r], FMA(hon, con[r], rr));                                         \
    n_on[r] = hon;                                                                                  \
    n_off[r] = hoff;                                                                                \
    d_out[r] = d;

/* One batch element's row of hw pixels; restrict-qualified so the loop vectorises. */
#define STEP_ROW(NAME, REAL, FLOOR, FMA, LOWPASS)                                                   \
    FSDVS_CLONES static void NAME(                                                                  \
        const REAL *restrict target, const REAL *restrict lp, const REAL *restrict em1,             \
        const REAL *restrict ref, const REAL *restrict con, const REAL *restrict coff, REAL dtb,    \
        REAL leak, REAL eps, int64_t hw, REAL *restrict lp_out, REAL *restrict ref_out,             \
        REAL *restrict n_on, REAL *restrict n_off, REAL *restrict d_out) {                          \
        for (int64_t r = 0; r < hw; r++) {                                                          \
            REAL tg = target[r];                                                                    \
            if (LOWPASS) {                                                                          \
                REAL l = lp[r];                                                                     \
                tg = l + (-em1[r]) * (tg - l);                                                      \
                lp_out[r] = tg;                                                                     \
            }                                                                                       \
            COMPARATOR(REAL, FLOOR, FMA)                                                            \
        }                                                                                           \
    }

STEP_ROW(step_row_lp_f32, float, floorf, fmaf, 1)
STEP_ROW(step_row_f32, float, floorf, fmaf, 0)
STEP_ROW(step_row_lp_f64, double, floor, fma, 1)
STEP_ROW(step_row_f64, double, floor, fma, 0)

#define PIXEL_STEP(NAME, REAL, ROW_LP, ROW)                                                         \
    void NAME(const REAL *target, const REAL *lp, const REAL *em1, const REAL *ref,                 \
              const REAL *c_on, int64_t n_c_on, const REAL *c_off, int64_t n_c_off, const REAL *dt, \
              REAL leak, REAL eps, int64_t n_pix, int64_t hw, REAL *lp_out, REAL *ref_out,          \
              REAL *n_on, REAL *n_off, REAL *d_out) {                                               \
        int64_t n_b = hw > 0 ? n_pix / hw : 0;                                                      \
        for (int64_t b = 0; b < n_b; b++) {                                                         \
            int64_t o = b * hw;                                                                     \
            const REAL *con = n_c_on == hw ? c_on : c_on + o;                                       \
            const REAL *coff = n_c_off == hw ? c_off : c_off + o;                                   \
            if (em1)                                                                                \
                ROW_LP(target + o, lp + o, em1 + o, ref + o, con, coff, dt[b], leak, eps, hw,       \
                       lp_out + o, ref_out + o, n_on + o, n_off + o, d_out + o);                    \
            else                                                                                    \
                ROW(target + o, NULL, NULL, ref + o, con, coff, dt[b], leak, eps, hw, NULL,         \
                    ref_out + o, n_on + o, n_off + o, d_out + o);                                   \
        }                                                                                           \
    }

PIXEL_STEP(fsdvs_pixel_step_f32, float, step_row_lp_f32, step_row_f32)
PIXEL_STEP(fsdvs_pixel_step_f64, double, step_row_lp_f64, step_row_f64)

/* v2e's linear-log response (pixel.linlog_v2e), in two passes around torch's log.
 * linlog_clamp: xc = max(I * dn, knee_dn) (torch.clamp(x, min=k); a NaN stays NaN).
 * linlog_finish: x = I * dn; y = x <= knee_dn ? x * slope : lg; out = (REAL) (round((double) y *
 * 1e8) / 1e8), the rounding to even done as pixel._round_half_even does: (v + M) - M, M = 1.5 2^52
 * (exact for |v| < 2^51). lg holds torch.log of linlog_clamp's output; out may be lg. */
#define LINLOG(CLAMP, FINISH, REAL)                                                                 \
    FSDVS_CLONES void CLAMP(const REAL *restrict inten, int64_t n, REAL dn, REAL knee_dn,           \
                            REAL *restrict xc) {                                                    \
        for (int64_t i = 0; i < n; i++) {                                                           \
            REAL x = inten[i] * dn;                                                                 \
            xc[i] = x < knee_dn ? knee_dn : x;                                                      \
        }                                                                                           \
    }                                                                                               \
    FSDVS_CLONES void FINISH(const REAL *restrict inten, const REAL *lg, int64_t n, REAL dn,        \
                             REAL knee_dn, REAL slope, double magic, REAL *out) {                   \
        for (int64_t i = 0; i < n; i++) {                                                           \
            REAL x = inten[i] * dn;                                                                 \
            REAL y = x <= knee_dn ? x * slope : lg[i];                                              \
            double v = (double)y * 1e8;                                                             \
            v = (v + magic) - magic;                                                                \
            out[i] = (REAL)(v / 1e8);                                                               \
        }                                                                                           \
    }

LINLOG(fsdvs_linlog_clamp_f32, fsdvs_linlog_finish_f32, float)
LINLOG(fsdvs_linlog_clamp_f64, fsdvs_linlog_finish_f64, double)

/* The positivity floor (filtering._FloorSTE forward and its count): out = max(x, floor) (a NaN
 * stays NaN, as torch.clamp), returning how many x < floor. */
#define FLOOR_COUNT(NAME, REAL)                                                                     \
    FSDVS_CLONES int64_t NAME(const REAL *restrict x, int64_t n, REAL floor_v, REAL *restrict out) { \
        int64_t below = 0;                                                                          \
        for (int64_t i = 0; i < n; i++) {                                                           \
            REAL v = x[i];                                                                          \
            int lo = v < floor_v;                                                                   \
            below += lo;                                                                            \
            out[i] = lo ? floor_v : v;                                                              \
        }                                                                                           \
        return below;                                                                               \
    }

FLOOR_COUNT(fsdvs_floor_count_f32, float)
FLOOR_COUNT(fsdvs_floor_count_f64, double)
