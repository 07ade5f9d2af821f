/* Compiled kernels of fsdvs_hw/sensor/simulation/crossings.py: one comparator step's events and one frame
 * interval's stable time sort, on CPU arrays (built and loaded by library.py).
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

#include "_native_clones.h"

#define BIG_BUCKET 32

/* Events of one step in input order (ON pixels first, raster order, each pixel's events
 * consecutive). Arrays are over the n_pix = B*H*W flattened pixels; c_on/c_off hold 1, H*W or
 * B*H*W values; t_a, t_b, dt hold B values. last_t is updated in place when use_refr. em_on/em_off
 * (NULL: not wanted) receive the emitted counts. flat/t/p (NULL unless collecting) need room for
 * every emitted event. Returns the number of events written; *lost receives the crossings lost to
 * the refractory period. */
#define STEP_EVENTS(NAME, REAL)                                                          \
    FSDVS_CLONES int64_t NAME(const REAL *h_on, const REAL *h_off, const REAL *sig_a, const REAL *ref_a,         \
                 const REAL *d_b, const REAL *c_on, int64_t n_c_on, const REAL *c_off,               \
                 int64_t n_c_off, const double *t_a, const double *t_b, const double *dt,           \
                 int64_t n_pix, int64_t hw, double *last_t, double refr, int use_refr,               \
                 REAL *em_on, REAL *em_off, int32_t *flat, double *t, int8_t *p, double *lost) {    \
        int64_t k = 0;                                                                              \
        double lost_sum = 0.0;                                                                      \
        int64_t n_b = hw > 0 ? n_pix / hw : 0;                                                    \
        int32_t *act = malloc(sizeof(int32_t) * (hw > 0 ? hw : 1));                                 \
        if (!act) return -1;                                                                        \
        for (int pol = 0; pol < 2; pol++) {                                                         \
            const REAL *h = pol == 0 ? h_on : h_off;                                                \
            const REAL *c = pol == 0 ? c_on : c_off;                                                \
            int64_t n_c = pol == 0 ? n_c_on : n_c_off;                                              \
            REAL *em = pol == 0 ? em_on : em_off;                                                   \
            int8_t sign = pol == 0 ? 1 : -1;                                                        \
            /* batch element outside, pixel inside: no division per pixel */                       \
            for (int64_t b = 0; b < n_b; b++) {                                                     \
            double ta = t_a[b], dtb = dt[b], hi_t = t_b[b];                                         \
            double lo = nextafter(ta, INFINITY);                                                    \
            const REAL *cb = n_c == 1 ? c : (n_c == hw ? c : c + b * hw);                           \
            int64_t cstride = n_c == 1 ? 0 : 1;                                                     \
            /* the active pixels first, without a branch per pixel (activity is unpredictable) */  \
            int64_t n_act = 0;                                                                      \
            for (int64_t r = 0; r < hw; r++) {                                                      \
                act[n_act] = (int32_t)r;                                                            \
                n_act += h[b * hw + r] > 0;                                                         \
            }                                                                                       \
            for (int64_t a = 0; a < n_act; a++) {                                                   \
                int64_t r = act[a], i = b * hw + r;                                                 \
                REAL hi = h[i];                                                                     \
                double n = (double)hi;                                                              \
                REAL da_r = sig_a[i] - ref_a[i];                                                    \
                double da = (double)da_r;                                                           \
                double v = ((double)d_b[i] - da) / dtb;                                             \
                if (sign < 0) {                                                                     \
                    da = -da;                                                                       \
                    v = -v;                                                                         \
                }                                                                                   \
                double cc = (double)cb[r * cstride];                                                \
                int rising = v > 0;                                                                 \
                double j0 = 1.0, m = 1.0, emitted;                                                  \
                if (!use_refr) {                                                                    \
                    emitted = rising ? n : 0.0;                                                     \
                } else {                                                                            \
                    double vs = rising ? v : 1.0;                                                   \
                    /* x <= cc (cc > 0) gives x / cc <= 1 (rounding is monotone), so ceil <= 1 and   \
                     * the clamp makes it 1: the division is skipped, not changed. Most pixels have   \
                     * not fired within the refractory period and change slowly: j0 = m = 1. */      \
                    double xj = vs * (last_t[i] + refr - ta) + da, xm = refr * vs;                  \
                    j0 = cc > 0 && xj <= cc ? 1.0 : ceil(xj / cc);                                  \
                    if (!(j0 >= 1.0)) j0 = 1.0;                                                     \
                    m = cc > 0 && xm <= cc ? 1.0 : ceil(xm / cc);                                   \
                    if (!(m >= 1.0)) m = 1.0;                                                       \
                    /* n and j0 are whole numbers: (n - j0) / 1 is exact and its floor itself */     \
                    emitted = n >= j0 ? 1.0 + (m == 1.0 ? n - j0 : floor((n - j0) / m)) : 0.0;      \
                    if (!rising) emitted = 0.0;                                                     \
                    if (emitted > 0) {                                                              \
                        double j_last = j0 + (emitted - 1.0) * m;                                   \
                        last_t[i] = ta + (j_last * cc - da) / vs;                                   \
                    }                                                                               \
                    lost_sum += n - emitted;                                                        \
                }                                                                                   \
                if (em) em[i] = (REAL)emitted;                                                      \
                if (!flat || !(emitted > 0)) continue;                                              \
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
            }                                                                                       \
        }                                                                                           \
        free(act);                                                                                  \
        *lost = lost_sum;                                                                           \
        return k;                                                                                   \
    }

STEP_EVENTS(fsdvs_step_events_f32, float)
STEP_EVENTS(fsdvs_step_events_f64, double)

/* Bucket of a time: floor((t - lo) * scale) clamped into [0, nb - 1]; monotone in t. */
static inline int64_t bucket_of(double tt, double lo, double scale, int64_t nb) {
    double f = (tt - lo) * scale;
    if (!(f > 0)) return 0; /* also NaN */
    if (f >= (double)nb) return nb - 1;
    return (int64_t)f;
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


/* One event of an interval being sorted: its time, flat pixel index and polarity in one 16-byte
 * record, so the bucket scatter touches one cache line per event instead of three. */
typedef struct {
    double t;
    int32_t flat;
    int8_t p;
} event_rec;

/* Stable merge sort of the records a[0:n] by t, using b as scratch; returns the result's array. */
static event_rec *merge_sort_rec(event_rec *a, event_rec *b, int64_t n) {
    for (int64_t width = 1; width < n; width *= 2) {
        for (int64_t lo = 0; lo < n; lo += 2 * width) {
            int64_t mid = lo + width < n ? lo + width : n;
            int64_t hi = lo + 2 * width < n ? lo + 2 * width : n;
            int64_t i = lo, j = mid, o = lo;
            while (i < mid && j < hi) b[o++] = a[j].t < a[i].t ? a[j++] : a[i++];
            while (i < mid) b[o++] = a[i++];
            while (j < hi) b[o++] = a[j++];
        }
        event_rec *s = a;
        a = b;
        b = s;
    }
    return a;
}

/* Stable sort by time of one frame interval's events, given as n_parts parts (concatenated in
 * order), into the records rec (room for every event): a counting sort into nb buckets
 * (bucket_of is monotone in time, so buckets are ordered), one scatter of each event into its
 * bucket's next record, then a stable sort inside the buckets. counts: scratch of nb + 1 entries.
 * Returns the number of events, or -1 when a scratch allocation failed. */
static int64_t sort_records(int64_t n_parts, const int64_t *lens, const int32_t *const *flats,
                            const double *const *ts, const int8_t *const *ps, double lo, double scale, int64_t nb,
                            int32_t *counts, event_rec *rec) {
    int64_t n = 0;
    for (int64_t b = 0; b <= nb; b++) counts[b] = 0;
    for (int64_t q = 0; q < n_parts; q++) {
        n += lens[q];
        for (int64_t i = 0; i < lens[q]; i++) counts[bucket_of(ts[q][i], lo, scale, nb) + 1]++;
    }
    for (int64_t b = 0; b < nb; b++) counts[b + 1] += counts[b];
    for (int64_t q = 0; q < n_parts; q++) {
        const int32_t *f = flats[q];
        const double *t = ts[q];
        const int8_t *p = ps[q];
        for (int64_t i = 0; i < lens[q]; i++) {
            event_rec *r = rec + counts[bucket_of(t[i], lo, scale, nb)]++;
            r->t = t[i];
            r->flat = f[i];
            r->p = p[i];
        }
    }
    /* counts[b] is now the end of bucket b: bucket b is [counts[b - 1], counts[b]). Big buckets
     * are merge-sorted first; then one insertion pass over the whole interval finishes the small
     * ones: a time in a later bucket is strictly greater (bucket_of is monotone), so no event
     * moves out of its bucket and the pass costs one comparison per event where it is in order. */
    for (int64_t b = 0; b < nb; b++) {
        int64_t s = b ? counts[b - 1] : 0, len = counts[b] - s;
        if (len <= BIG_BUCKET) continue;
        event_rec *tmp = malloc(sizeof(event_rec) * len);
        if (!tmp) return -1;
        event_rec *sorted = merge_sort_rec(rec + s, tmp, len);
        if (sorted != rec + s)
            for (int64_t i = 0; i < len; i++) rec[s + i] = sorted[i];
        free(tmp);
    }
    for (int64_t i = 1; i < n; i++) {
        if (!(rec[i].t < rec[i - 1].t)) continue;
        event_rec ri = rec[i];
        int64_t j = i - 1;
        while (j >= 0 && rec[j].t > ri.t) {
            rec[j + 1] = rec[j];
            j--;
        }
        rec[j + 1] = ri;
    }
    return n;
}

/* sort_records, then the records into flat_out, t_out, p_out. Returns 0, or -1 (out of memory). */
int fsdvs_sort_interval(int64_t n_parts, const int64_t *lens, const int32_t *const *flats,
                        const double *const *ts, const int8_t *const *ps, double lo, double scale, int64_t nb,
                        int32_t *counts, event_rec *rec, int32_t *flat_out, double *t_out, int8_t *p_out) {
    int64_t n = sort_records(n_parts, lens, flats, ts, ps, lo, scale, nb, counts, rec);
    if (n < 0) return -1;
    for (int64_t i = 0; i < n; i++) {
        flat_out[i] = rec[i].flat;
        t_out[i] = rec[i].t;
        p_out[i] = rec[i].p;
    }
    return 0;
}

/* sort_records, then the records into the event columns x, y (int64), t, p with
 * y = (f mod hw) / w, x = (f mod hw) - y w. Returns 0, or -1 (out of memory). */
int fsdvs_sort_interval_columns(int64_t n_parts, const int64_t *lens, const int32_t *const *flats,
                                const double *const *ts, const int8_t *const *ps, double lo, double scale,
                                int64_t nb, int32_t *counts, event_rec *rec, int64_t hw, int64_t w,
                                int64_t *x_out, int64_t *y_out, double *t_out, int8_t *p_out) {
    int64_t n = sort_records(n_parts, lens, flats, ts, ps, lo, scale, nb, counts, rec);
    if (n < 0) return -1;
    int32_t hw32 = (int32_t)hw, w32 = (int32_t)w;
    for (int64_t i = 0; i < n; i++) {
        int32_t f = rec[i].flat;
        if (f >= hw32) f %= hw32;
        int32_t yy = f / w32;
        y_out[i] = yy;
        x_out[i] = f - yy * w32;
        t_out[i] = rec[i].t;
        p_out[i] = rec[i].p;
    }
    return 0;
}
