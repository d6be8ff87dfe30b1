/* The scoring DPs in C, without numba's import (~0.45 s per process):
 *   - jm_dp_i16: the max-plus DP of the exact host (jaxmatch/kernels/backends.py, c_values), the
 *     numba kernel's steps (jaxmatch/kernels/dp_numba.py) in int16, chunks of meshes as the
 *     lanes, so its values are bit for bit the numba kernel's;
 *   - jm_align_f32: one orientation's alignment (jaxmatch/scoring/exact.py, align): the float32
 *     rows of exact.dp_rows, the same operations in the same order, and align's backtrack.
 * Arrays are C-contiguous. The module init makes it importable (its __file__ locates the
 * library, loaded with ctypes); it exports no Python functions. */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <stdlib.h>

typedef int64_t i64;

/* One input point's band of a chunk's DP: rows hi down to lo of d (n + 1, L), row j from row
 * j - 1 plus the weights of vertex (r + j - 1) % n (wc: (n, L), one code); with strict, the skip
 * branch capped at the gate g first. Inlined with strict a constant, so each variant's lane loop
 * is compiled (and vectorised) on its own. */
static inline __attribute__((always_inline)) void band(int16_t *d, const int16_t *wc, i64 n, i64 L, i64 nl, i64 r,
                                                       i64 lo, i64 hi, const int strict, const int16_t g) {
    for (i64 j = hi; j >= lo; j--) {
        int16_t *restrict dj = d + j * L;
        const int16_t *restrict dm = d + (j - 1) * L;
        const int16_t *restrict w = wc + ((r + j - 1) % n) * L;
        for (i64 l = 0; l < nl; l++) {
            int16_t x = (int16_t)(dm[l] + w[l]);
            int16_t y = strict ? (dj[l] < g ? dj[l] : g) : dj[l];
            dj[l] = x > y ? x : y;
        }
    }
}

/* codes (S, mpad) int32; lengths (S,) int64 (<= mpad); vals (N, n) int32 valences 2..5;
 * tab (4, 64) int16; gate (4,) int16; out (S, N, 2n) int16; lanes: meshes per chunk (the numba
 * kernel's LANES: the weights (2, 4, n, lanes) and the row (n + 1, lanes) of a chunk stay in
 * cache, whatever N). Returns 0, or -1 out of memory. */
int jm_dp_i16(const int32_t *codes, i64 S, i64 mpad, const i64 *lengths, const int32_t *vals, i64 N, i64 n,
              const int16_t *tab, const int16_t *gate, int strict, i64 lanes, int16_t *out) {
    if (N <= 0 || S <= 0 || n <= 0) return 0;
    if (lanes < 1) lanes = 1;
    if (lanes > N) lanes = N;
    const int16_t neg = tab[3 * 64];
    const i64 L = lanes;
    int16_t *pv = (int16_t *)malloc(sizeof(int16_t) * 2 * 4 * (size_t)n * (size_t)L);
    int16_t *d = (int16_t *)malloc(sizeof(int16_t) * (size_t)(n + 1) * (size_t)L);
    if (!pv || !d) {
        free(pv);
        free(d);
        return -1;
    }
    for (i64 b0 = 0; b0 < N; b0 += L) {
        const i64 nl = N - b0 < L ? N - b0 : L; /* lanes of this chunk */
        for (i64 bl = 0; bl < nl; bl++) {
            const int32_t *vb = vals + (b0 + bl) * n;
            for (i64 k = 0; k < n; k++) {
                int a = vb[(k + 1) % n] - 2, v = vb[k] - 2, c0 = vb[(k - 1 + n) % n] - 2;
                int t = a * 16 + v * 4 + c0;  /* triple [s[k+1], s[k], s[k-1]] */
                int tr = c0 * 16 + v * 4 + a; /* in vals[::-1] vertex k sits at n - 1 - k, neighbours swapped */
                for (int c = 0; c < 4; c++) {
                    pv[((0 * 4 + c) * n + k) * L + bl] = tab[c * 64 + t];
                    pv[((1 * 4 + c) * n + (n - 1 - k)) * L + bl] = tab[c * 64 + tr];
                }
            }
        }
        for (i64 s = 0; s < S; s++) {
            const i64 m = lengths[s];
            const int32_t *cs = codes + s * mpad;
            for (i64 o = 0; o < 2 * n; o++) {
                const i64 h = o < n ? 0 : 1, r = o - h * n;
                for (i64 l = 0; l < nl; l++) d[l] = 0;
                for (i64 j = 1; j <= n; j++)
                    for (i64 l = 0; l < nl; l++) d[j * L + l] = neg;
                int16_t z = 0;
                for (i64 i = 0; i < m; i++) {
                    const int c = cs[i];
                    i64 lo = n - m + i + 1, hi = i + 1;
                    if (lo < 1) lo = 1;
                    if (hi > n) hi = n;
                    const int16_t *wc = pv + (h * 4 + c) * n * L;
                    if (strict) {
                        const int16_t g = gate[c];
                        band(d, wc, n, L, nl, r, lo, hi, 1, g);
                        if (z > g) {
                            z = g;
                            for (i64 l = 0; l < nl; l++) d[l] = z;
                        }
                    } else {
                        band(d, wc, n, L, nl, r, lo, hi, 0, 0);
                    }
                }
                const int16_t *dn = d + n * L;
                for (i64 l = 0; l < nl; l++) out[(s * N + b0 + l) * 2 * n + o] = dn[l];
            }
        }
    }
    free(pv);
    free(d);
    return 0;
}

/* codes (m,) int32 in 0..2; seq (n,) int64 valences 2..5 in matched order; table (3, 64) float32
 * (the shifted frame, NEG where forbidden); must (3,) uint8; neg = NEG. out (n,) int32: the input
 * point each vertex takes. Returns 0, 1 when no alignment is finite (D[m][n] <= neg / 2), -1 out of
 * memory. */
int jm_align_f32(const int32_t *codes, i64 m, const i64 *seq, i64 n, const float *table, const uint8_t *must,
                 float neg, int32_t *out) {
    const i64 w = n + 1;
    float *rows = (float *)malloc(sizeof(float) * (size_t)(m + 1) * (size_t)w);
    float *wc = (float *)malloc(sizeof(float) * 3 * (size_t)(n > 0 ? n : 1));
    if (!rows || !wc) {
        free(rows);
        free(wc);
        return -1;
    }
    for (i64 j = 0; j < n; j++) {
        i64 t = (seq[(j + 1) % n] - 2) * 16 + (seq[j] - 2) * 4 + (seq[(j - 1 + n) % n] - 2); /* [s[j+1], s[j], s[j-1]] */
        for (int c = 0; c < 3; c++) wc[c * n + j] = table[c * 64 + t];
    }
    float gate[3];
    for (int c = 0; c < 3; c++) gate[c] = must[c] ? neg : 0.0f;
    rows[0] = 0.0f;
    for (i64 j = 1; j <= n; j++) rows[j] = neg;
    for (i64 i = 0; i < m; i++) {
        const float *prev = rows + i * w;
        float *cur = rows + (i + 1) * w;
        const int c = codes[i];
        const float g = gate[c];
        const float *wi = wc + c * n;
        for (i64 j = 1; j <= n; j++) {
            float skip = prev[j] + g, take = prev[j - 1] + wi[j - 1];
            cur[j] = skip >= take ? skip : take; /* np.maximum */
        }
        cur[0] = prev[0] + g;
    }
    int rc = 0;
    if ((double)rows[m * w + n] <= (double)neg / 2.0) {
        rc = 1;
    } else {
        i64 i = m, j = n;
        while (j > 0) {
            if (i > j && !must[codes[i - 1]] && rows[i * w + j] == rows[(i - 1) * w + j]) {
                i -= 1; /* skip input point i - 1 */
            } else {
                out[j - 1] = (int32_t)(i - 1);
                i -= 1;
                j -= 1;
            }
        }
    }
    free(rows);
    free(wc);
    return rc;
}

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_dp",
                                    "jaxmatch's compiled scoring DP (called through ctypes)", -1, NULL};

PyMODINIT_FUNC PyInit__dp(void) { return PyModule_Create(&module); }
