/* Compiled placement kernels of jaxmatch (C, built with the package; called through ctypes by
 * jaxmatch/kernels/placement.py).
 *
 * The same algorithms as the numpy references in embed.py and choose.py, step for step:
 *   - the smoother: regularised corner condition numbers (power mean), their gradient, the
 *     sliding-vertex parametrisation (softmax of gap logits), L-BFGS with Armijo backtracking,
 *     and the untangle + power-continuation loop keeping the best positions seen;
 *   - the dense Tutte solve (Cholesky);
 *   - the alignment DPs: utilities of every orientation, and per orientation the best utility,
 *     the least gap cost and its tied alignments in depth-first order.
 * Why C and not numba here: a process pays ~0.55 s to import numba and load its cached code
 * before the first placement (docs/perf.md); this library loads in milliseconds.
 *
 * GNU C (GCC or Clang): the energy computes two corners per vector instruction with GNU C vector
 * types; a compiler without them does not build the library (the numba fallback then smooths).
 * Arrays are C-contiguous: double, or int64_t for indices. The module init makes it importable
 * (its __file__ locates the library); it exports no Python functions.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

typedef int64_t i64;

/* ------------------------------------------------------------------------------------------ */
/* the smoother */

static inline void corner(const double *pos, const i64 *quads, i64 q, int c, i64 *p, i64 *nx, i64 *pv,
                          double *e1x, double *e1y, double *e2x, double *e2y) {
    *p = quads[4 * q + c];
    *nx = quads[4 * q + (c + 1) % 4];
    *pv = quads[4 * q + (c + 3) % 4];
    *e1x = pos[2 * *nx] - pos[2 * *p];
    *e1y = pos[2 * *nx + 1] - pos[2 * *p + 1];
    *e2x = pos[2 * *pv] - pos[2 * *p];
    *e2y = pos[2 * *pv + 1] - pos[2 * *p + 1];
}

/* the softmax of x[off .. off + count): w[i] = exp(x[off + i] - max) / total (w: (count,)) */
static inline void softmax(const double *x, i64 off, i64 count, double *w) {
    double m = -INFINITY, t = 0.0;
    for (i64 i = 0; i < count; i++) m = fmax(m, x[off + i]);
    for (i64 i = 0; i < count; i++) {
        w[i] = exp(x[off + i] - m);
        t += w[i];
    }
    for (i64 i = 0; i < count; i++) w[i] = w[i] / t;
}

typedef struct {
    i64 V, F, nf, S;
    const double *base; /* (V, 2) */
    const i64 *quads;   /* (F, 4) */
    const i64 *free_;   /* (nf,) */
    const double *sa, *sb; /* (S, 2) */
    const i64 *sp, *sv; /* (S + 1,), (R,) */
    double *w; /* (R + S,) scratch: the softmax weights of the last positions() */
} Problem;

/* positions (V, 2) of the flat vector x; the slides' softmax weights into P->w */
static void positions(const Problem *P, const double *x, double *pos) {
    memcpy(pos, P->base, sizeof(double) * 2 * P->V);
    for (i64 i = 0; i < P->nf; i++) {
        pos[2 * P->free_[i]] = x[2 * i];
        pos[2 * P->free_[i] + 1] = x[2 * i + 1];
    }
    i64 off = 2 * P->nf;
    for (i64 s = 0; s < P->S; s++) {
        i64 r = P->sp[s + 1] - P->sp[s];
        double *w = P->w + (off - 2 * P->nf);
        softmax(x, off, r + 1, w);
        double u = 0.0, dx = P->sb[2 * s] - P->sa[2 * s], dy = P->sb[2 * s + 1] - P->sa[2 * s + 1];
        for (i64 i = 0; i < r; i++) {
            u += w[i];
            i64 v = P->sv[P->sp[s] + i];
            pos[2 * v] = P->sa[2 * s] + u * dx;
            pos[2 * v + 1] = P->sa[2 * s + 1] + u * dy;
        }
        off += r + 1;
    }
}

/* two doubles as one GNU C vector (GCC, Clang; an SSE2 register): the arithmetic operators act
   lane by lane with the IEEE operations of scalar code (no contraction: the build targets no FMA) */
typedef double v2 __attribute__((vector_size(16)));
typedef int64_t v2i __attribute__((vector_size(16)));

static inline v2 ld2(const double *p) {
    v2 a;
    memcpy(&a, p, sizeof a);
    return a;
}

static inline void st2(double *p, v2 a) { memcpy(p, &a, sizeof a); }

/* lane by lane m ? a : b, m a comparison's lanes (all ones or zero) */
static inline v2 vselect(v2i m, v2 a, v2 b) { return (v2)((m & (v2i)a) | (~m & (v2i)b)); }

/* the correctly rounded square root of each lane (sqrt's value: IEEE rounds it exactly) */
static inline v2 vsqrt(v2 a) {
#if defined(__SSE2__)
    return (v2)_mm_sqrt_pd((__m128d)a);
#else
    return (v2){sqrt(a[0]), sqrt(a[1])};
#endif
}

/* e where power == 2^e (0 <= e < 7), else -1 (then powsq calls pow) */
static int squarings(double power) {
    int sq = -1;
    for (int e = 0; e < 7; e++)
        if (power == ldexp(1.0, e)) sq = e;
    return sq;
}

static inline double powsq(double x, double power, int squarings) {
    if (squarings < 0) return pow(x, power);
    for (int i = 0; i < squarings; i++) x = x * x;
    return x;
}

/* The energy in two passes: energy_value at pos (INFINITY where not finite), keeping each corner's
   k, r, h ((F, 4) scratch) and edge vectors e ((F, 4, 4) scratch: per quad e1x, e1y, e2x, e2y of its
   four corners); then, only where needed (a line search asks for the gradient of accepted points
   alone), energy_grad: the gradient (V, 2) from what the value pass kept, and f, or INFINITY (grad
   zero) where the gradient is not finite. sq: squarings(power). Written a quad at a time, its corners
   two by two in the lanes of a v2 (each lane the same IEEE operations as one corner in scalar code,
   so the same doubles), the sums in corner order. */
static double energy_value(const double *pos, const i64 *quads, i64 F, double delta, double power, int sq, double *k,
                           double *r, double *h, double *e) {
    double d2 = 4.0 * delta * delta, kmax = -INFINITY;
    for (i64 q = 0; q < F; q++) {
        const i64 *v = quads + 4 * q;
        double *eq = e + 16 * q;
        double X0 = pos[2 * v[0]], X1 = pos[2 * v[1]], X2 = pos[2 * v[2]], X3 = pos[2 * v[3]];
        double Y0 = pos[2 * v[0] + 1], Y1 = pos[2 * v[1] + 1], Y2 = pos[2 * v[2] + 1], Y3 = pos[2 * v[3] + 1];
        /* corners (0, 1), then (2, 3): the corner, its next and previous vertices */
        v2 xs[2][3] = {{{X0, X1}, {X1, X2}, {X3, X0}}, {{X2, X3}, {X3, X0}, {X1, X2}}};
        v2 ys[2][3] = {{{Y0, Y1}, {Y1, Y2}, {Y3, Y0}}, {{Y2, Y3}, {Y3, Y0}, {Y1, Y2}}};
        for (int j = 0; j < 2; j++) {
            int c = 2 * j;
            v2 e1x = xs[j][1] - xs[j][0], e1y = ys[j][1] - ys[j][0];
            v2 e2x = xs[j][2] - xs[j][0], e2y = ys[j][2] - ys[j][0];
            v2 a = e1x * e2y - e1y * e2x;
            v2 rr = vsqrt(a * a + d2);
            v2 hh = 0.5 * (a + rr);
            if (!(a[0] >= 0 && a[1] >= 0)) hh = vselect(a >= 0.0, hh, d2 / (2.0 * (rr - a)));
            v2 N = e1x * e1x + e1y * e1y + e2x * e2x + e2y * e2y;
            v2 kq = N / (2.0 * hh);
            st2(eq + c, e1x);
            st2(eq + 4 + c, e1y);
            st2(eq + 8 + c, e2x);
            st2(eq + 12 + c, e2y);
            st2(r + 4 * q + c, rr);
            st2(h + 4 * q + c, hh);
            st2(k + 4 * q + c, kq);
            /* as "if (!(kq <= kmax)) kmax = kq" (a NaN taken) but for which of two equal zeros is kept,
               which the test below treats alike: no branch (maxsd) */
            kmax = kmax > kq[0] ? kmax : kq[0];
            kmax = kmax > kq[1] ? kmax : kq[1];
        }
    }
    if (!(isfinite(kmax) && kmax > 0)) return INFINITY;
    double C = 4.0 * (double)F;
    double acc = 0.0;
    switch (sq) { /* powsq's squarings written out: the same products, no inner loop */
#define ACC(expr)                                                                                                      \
    for (i64 i = 0; i < 4 * F; i++) {                                                                                  \
        double t = k[i] / kmax;                                                                                        \
        acc += (expr);                                                                                                 \
    }                                                                                                                  \
    break;
    case 0: ACC(t)
    case 1: ACC(t * t)
    case 2: ACC((t = t * t, t * t))
    case 3: ACC((t = t * t, t = t * t, t * t))
    case 4: ACC((t = t * t, t = t * t, t = t * t, t * t))
    default:
        for (i64 i = 0; i < 4 * F; i++) acc += powsq(k[i] / kmax, power, sq);
#undef ACC
    }
    double f = kmax * pow(acc / C, 1.0 / power);
    return isfinite(f) ? f : INFINITY;
}

static double energy_grad(const i64 *quads, i64 V, i64 F, double power, int sq, double f, double *grad,
                          const double *k, const double *r, const double *h, const double *e) {
    double C = 4.0 * (double)F;
    memset(grad, 0, sizeof(double) * 2 * V);
    for (i64 q = 0; q < F; q++) {
        const i64 *v = quads + 4 * q;
        const double *eq = e + 16 * q, *kq = k + 4 * q;
        v2 x[2] = {ld2(kq) / f, ld2(kq + 2) / f}, dk[2];
        if (sq >= 0 && x[0][0] > 0 && x[0][1] > 0 && x[1][0] > 0 && x[1][1] > 0)
            for (int j = 0; j < 2; j++) {
                v2 t = x[j];
                for (int s = 0; s < sq; s++) t = t * t;
                dk[j] = t / x[j] / C;
            }
        else
            for (int c = 0; c < 4; c++) {
                double xc = x[c >> 1][c & 1];
                dk[c >> 1][c & 1] = xc > 0 ? powsq(xc, power, sq) / xc / C : pow(kq[c] / f, power - 1.0) / C;
            }
        for (int j = 0; j < 2; j++) { /* corners 2j, 2j + 1 */
            int c = 2 * j;
            v2 e1x = ld2(eq + c), e1y = ld2(eq + 4 + c), e2x = ld2(eq + 8 + c), e2y = ld2(eq + 12 + c);
            v2 gN = dk[j] / (2.0 * ld2(h + 4 * q + c));
            v2 ga = -dk[j] * ld2(kq + c) / ld2(r + 4 * q + c);
            v2 g1x = 2.0 * gN * e1x + ga * e2y;
            v2 g1y = 2.0 * gN * e1y - ga * e2x;
            v2 g2x = 2.0 * gN * e2x - ga * e1y;
            v2 g2y = 2.0 * gN * e2y + ga * e1x;
            for (int l = 0; l < 2; l++) {
                i64 p = v[c + l], nx = v[(c + l + 1) & 3], pv = v[(c + l + 3) & 3];
                grad[2 * p] -= g1x[l] + g2x[l];
                grad[2 * p + 1] -= g1y[l] + g2y[l];
                grad[2 * nx] += g1x[l];
                grad[2 * nx + 1] += g1y[l];
                grad[2 * pv] += g2x[l];
                grad[2 * pv + 1] += g2y[l];
            }
        }
    }
    for (i64 v = 0; v < 2 * V; v++)
        if (!isfinite(grad[v])) {
            memset(grad, 0, sizeof(double) * 2 * V);
            return INFINITY;
        }
    return f;
}

/* energy at pos and its gradient into grad (V, 2); INFINITY (grad zero) where not finite */
static double energy(const double *pos, const i64 *quads, i64 V, i64 F, double delta, double power, int sq,
                     double *grad, double *k, double *r, double *h, double *e) {
    double f = energy_value(pos, quads, F, delta, power, sq, k, r, h, e);
    if (!isfinite(f)) {
        memset(grad, 0, sizeof(double) * 2 * V);
        return INFINITY;
    }
    return energy_grad(quads, V, F, power, sq, f, grad, k, r, h, e);
}

/* the gradient (n,) in x of a function of the positions, from its gradient gpos (V, 2) there
   (P->w: the weights positions() computed at x) */
static void pull(const Problem *P, const double *gpos, double *g, double *gu) {
    for (i64 i = 0; i < P->nf; i++) {
        g[2 * i] = gpos[2 * P->free_[i]];
        g[2 * i + 1] = gpos[2 * P->free_[i] + 1];
    }
    i64 off = 2 * P->nf;
    for (i64 s = 0; s < P->S; s++) {
        i64 r = P->sp[s + 1] - P->sp[s];
        const double *w = P->w + (off - 2 * P->nf);
        double dx = P->sb[2 * s] - P->sa[2 * s], dy = P->sb[2 * s + 1] - P->sa[2 * s + 1];
        double u = 0.0, dot = 0.0;
        for (i64 i = 0; i <= r; i++) gu[i] = 0.0;
        for (i64 i = 0; i < r; i++) {
            u += w[i];
            i64 v = P->sv[P->sp[s] + i];
            gu[i] = gpos[2 * v] * dx + gpos[2 * v + 1] * dy;
            dot += gu[i] * u;
        }
        double tail = 0.0;
        for (i64 i = r; i >= 0; i--) {
            tail += gu[i];
            g[off + i] = w[i] * (tail - dot);
        }
        off += r + 1;
    }
}

/* every buffer the smoother needs, allocated once a call: the objective's (pos, gpos: (V, 2); k, r, h:
   (F, 4); e: (F, 4, 4); gu, w: (n + 1,)) and L-BFGS's (g, q, xn, gn: (n,); Sm, Ym: (mem, n); crho, ca,
   rho, sy, yy: (mem,)) */
typedef struct {
    double *pos, *gpos, *k, *r, *h, *e, *gu, *w;
    double *g, *q, *xn, *gn, *Sm, *Ym, *crho, *ca, *rho, *sy, *yy;
} Scratch;

static int scratch_alloc(Scratch *W, i64 V, i64 F, i64 n, i64 mem) {
    i64 v = V > 0 ? V : 1, f = F > 0 ? F : 1, m = mem > 0 ? mem : 1, nn = n > 0 ? n : 1;
    double **bufs[] = {&W->pos, &W->gpos, &W->k, &W->r, &W->h, &W->e, &W->gu, &W->w, &W->g, &W->q, &W->xn, &W->gn,
                       &W->Sm, &W->Ym, &W->crho, &W->ca, &W->rho, &W->sy, &W->yy};
    i64 sizes[] = {2 * v, 2 * v, 4 * f, 4 * f, 4 * f, 16 * f, n + 1, n + 1, nn, nn, nn, nn, m * nn, m * nn, m, m, m, m, m};
    int ok = 1;
    for (int i = 0; i < 19; i++) {
        *bufs[i] = malloc(sizeof(double) * sizes[i]);
        ok = ok && *bufs[i];
    }
    return ok;
}

static void scratch_free(Scratch *W) {
    double *bufs[] = {W->pos, W->gpos, W->k, W->r, W->h, W->e, W->gu, W->w, W->g, W->q, W->xn, W->gn,
                      W->Sm, W->Ym, W->crho, W->ca, W->rho, W->sy, W->yy};
    for (int i = 0; i < 19; i++) free(bufs[i]);
}

/* the objective at x (its value pass: objective_grad may follow for the same x); sq: squarings(power) */
static double objective_value(const Problem *P, const double *x, double delta, double power, int sq, Scratch *W) {
    positions(P, x, W->pos);
    return energy_value(W->pos, P->quads, P->F, delta, power, sq, W->k, W->r, W->h, W->e);
}

/* its gradient g (n,) at the x of the last objective_value, whose finite value f was; returns f, or
   INFINITY (g zero) where the gradient is not finite */
static double objective_grad(const Problem *P, double power, int sq, double f, double *g, Scratch *W, i64 n) {
    f = energy_grad(P->quads, P->V, P->F, power, sq, f, W->gpos, W->k, W->r, W->h, W->e);
    if (!isfinite(f)) {
        memset(g, 0, sizeof(double) * n);
        return INFINITY;
    }
    pull(P, W->gpos, g, W->gu);
    return f;
}

/* objective and gradient g (n,) at x; INFINITY (g zero) where not finite */
static double objective(const Problem *P, const double *x, double delta, double power, int sq, double *g, Scratch *W,
                        i64 n) {
    double f = objective_value(P, x, delta, power, sq, W);
    if (!isfinite(f)) {
        memset(g, 0, sizeof(double) * n);
        return INFINITY;
    }
    return objective_grad(P, power, sq, f, g, W, n);
}

static double dot(const double *a, const double *b, i64 n) {
    double s = 0.0;
    for (i64 i = 0; i < n; i++) s += a[i] * b[i];
    return s;
}

/* L-BFGS from x (n,), in place (its buffers in W). Each stored pair keeps s.y (the sum the step
   computed: the same double as dot(s, y)), 1 / s.y and y.y, so no iteration computes them again. */
static void lbfgs(const Problem *P, double *x, i64 n, double delta, double power, i64 maxiter, i64 mem, double ftol,
                  double gtol, Scratch *W) {
    double *g = W->g, *q = W->q, *xn = W->xn, *gn = W->gn, *Sm = W->Sm, *Ym = W->Ym, *crho = W->crho, *ca = W->ca,
           *rhos = W->rho, *sys = W->sy, *yys = W->yy;
    int sq = squarings(power);
    double f = objective(P, x, delta, power, sq, g, W, n);
    if (!isfinite(f)) return;
    i64 cnt = 0, head = 0;
    /* gmax: the largest |g[i]|; s_g: dot(newest s, g) where fresh (that pair stored by the last step:
       summed with it, the same terms in the same order) */
    double gmax = 0.0, s_g = 0.0;
    int fresh = 0;
    for (i64 i = 0; i < n; i++) {
        double a = fabs(g[i]);
        if (a > gmax) gmax = a; /* as fmax(gmax, a), which passes over a NaN too */
    }
    for (i64 it = 0; it < maxiter; it++) {
        if (gmax <= gtol) break;
        /* the two-loop recursion; each pass over q also sums the dot product the next step needs
           (the terms and order of dot()) */
        double d = 0.0;
        const double *nv = cnt > 0 ? Sm + (head + cnt - 1) % mem * n : NULL;
        if (nv && fresh) {
            memcpy(q, g, sizeof(double) * n);
            d = s_g;
        } else if (nv)
            for (i64 i = 0; i < n; i++) {
                q[i] = g[i];
                d += nv[i] * q[i];
            }
        else
            memcpy(q, g, sizeof(double) * n);
        for (i64 t = cnt - 1; t >= 0; t--) {
            i64 row = (head + t) % mem;
            double rho = rhos[row];
            double a = rho * d;
            const double *y = Ym + row * n;
            crho[t] = rho;
            ca[t] = a;
            if (t > 0) {
                nv = Sm + (head + t - 1) % mem * n;
                d = 0.0;
                for (i64 i = 0; i < n; i++) {
                    q[i] -= a * y[i];
                    d += nv[i] * q[i];
                }
            } else
                for (i64 i = 0; i < n; i++) q[i] -= a * y[i];
        }
        double sc = cnt > 0 ? sys[(head + cnt - 1) % mem] / yys[(head + cnt - 1) % mem] : 0.05 / fmax(gmax, 1e-300);
        nv = cnt > 0 ? Ym + head % mem * n : g;
        d = 0.0;
        for (i64 i = 0; i < n; i++) {
            q[i] *= sc;
            d += nv[i] * q[i];
        }
        for (i64 t = 0; t < cnt; t++) {
            double b = ca[t] - crho[t] * d;
            const double *sr = Sm + (head + t) % mem * n;
            nv = t + 1 < cnt ? Ym + (head + t + 1) % mem * n : g;
            d = 0.0;
            for (i64 i = 0; i < n; i++) {
                q[i] += sr[i] * b;
                d += nv[i] * q[i];
            }
        }
        double slope = -d; /* -dot(g, q) */
        if (!(slope < 0)) {
            cnt = 0;
            head = 0;
            double sc = 0.05 / fmax(gmax, 1e-300);
            for (i64 i = 0; i < n; i++) q[i] = g[i] * sc;
            slope = -dot(g, q, n);
        }
        double step = 1.0, fn;
        for (;;) {
            for (i64 i = 0; i < n; i++) xn[i] = x[i] - step * q[i];
            fn = objective_value(P, xn, delta, power, sq, W); /* the gradient only where the step is taken */
            if (isfinite(fn) && fn <= f + 1e-4 * step * slope) {
                fn = objective_grad(P, power, sq, fn, gn, W, n);
                if (isfinite(fn)) break;
            }
            step *= 0.5;
            if (step < 1e-12) return;
        }
        /* one pass for s.y, s.s, y.y, s.gn and the next gmax: independent sums, each in dot()'s order */
        double sy = 0.0, ss = 0.0, yy = 0.0, sgn = 0.0, gmn = 0.0;
        for (i64 i = 0; i < n; i++) {
            double si = xn[i] - x[i], yi = gn[i] - g[i], a = fabs(gn[i]);
            sy += si * yi;
            ss += si * si;
            yy += yi * yi;
            sgn += si * gn[i];
            if (a > gmn) gmn = a;
        }
        gmax = gmn;
        s_g = sgn;
        fresh = sy > 1e-12 * ss;
        if (fresh) {
            i64 row;
            if (cnt < mem) {
                row = (head + cnt) % mem;
                cnt++;
            } else {
                row = head;
                head = (head + 1) % mem;
            }
            for (i64 i = 0; i < n; i++) {
                Sm[row * n + i] = xn[i] - x[i];
                Ym[row * n + i] = gn[i] - g[i];
            }
            sys[row] = sy;
            rhos[row] = 1.0 / sy;
            yys[row] = yy;
        }
        int done = f - fn <= ftol * fmax(1.0, fabs(f));
        memcpy(x, xn, sizeof(double) * n);
        memcpy(g, gn, sizeof(double) * n);
        f = fn;
        if (done) break;
    }
}

static void start(const Problem *P, const double *xy, double *x) {
    for (i64 i = 0; i < P->nf; i++) {
        x[2 * i] = xy[2 * P->free_[i]];
        x[2 * i + 1] = xy[2 * P->free_[i] + 1];
    }
    i64 off = 2 * P->nf;
    for (i64 s = 0; s < P->S; s++) {
        i64 r = P->sp[s + 1] - P->sp[s];
        double dx = P->sb[2 * s] - P->sa[2 * s], dy = P->sb[2 * s + 1] - P->sa[2 * s + 1];
        double dd = dx * dx + dy * dy, prev = 0.0, tot = 0.0;
        for (i64 i = 0; i < r; i++) {
            i64 v = P->sv[P->sp[s] + i];
            double u = ((xy[2 * v] - P->sa[2 * s]) * dx + (xy[2 * v + 1] - P->sa[2 * s + 1]) * dy) / dd;
            x[off + i] = fmax(u - prev, 1e-12);
            prev = u;
        }
        x[off + r] = fmax(1.0 - prev, 1e-12);
        for (i64 i = 0; i <= r; i++) tot += x[off + i];
        for (i64 i = 0; i <= r; i++) x[off + i] = log(x[off + i] / tot);
        off += r + 1;
    }
}

typedef struct {
    i64 inv;
    double lo, mean;
} Key;

static Key quality_key(const double *xy, const i64 *quads, i64 F) {
    Key K = {0, INFINITY, 0.0};
    double tot = 0.0, tiny = 2.2250738585072014e-308;
    i64 p, nx, pv;
    double e1x, e1y, e2x, e2y;
    for (i64 q = 0; q < F; q++) {
        double sj = INFINITY;
        int bad = 0;
        for (int c = 0; c < 4; c++) {
            corner(xy, quads, q, c, &p, &nx, &pv, &e1x, &e1y, &e2x, &e2y);
            double a = e1x * e2y - e1y * e2x;
            if (a <= 0) bad = 1;
            double ln = sqrt(e1x * e1x + e1y * e1y) * sqrt(e2x * e2x + e2y * e2y);
            sj = fmin(sj, ln > tiny ? a / ln : 0.0);
        }
        sj = fmin(fmax(sj, -1.0), 1.0);
        K.inv += bad;
        K.lo = fmin(K.lo, sj);
        tot += sj;
    }
    K.mean = tot / (double)F;
    return K;
}

static int better(Key k, Key b, double tol) {
    if (k.inv != b.inv) return k.inv < b.inv;
    if (fabs(k.lo - b.lo) > tol) return k.lo > b.lo;
    return k.mean > b.mean + tol;
}

/* embed.smooth: best positions into out (V, 2); returns 0, or -1 when out of memory */
int jm_smooth(const double *xy, i64 V, const i64 *quads, i64 F, const i64 *free_, i64 nf, const double *sa,
              const double *sb, const i64 *sp, const i64 *sv, i64 S, i64 iters, const double *powers, i64 npow,
              i64 untangle_rounds, i64 mem, double ftol, double gtol, double *out) {
    Problem P = {V, F, nf, S, xy, quads, free_, sa, sb, sp, sv, NULL};
    i64 n = 2 * nf + (S ? sp[S] : 0) + S;
    Scratch W;
    double *cur = malloc(sizeof(double) * 2 * V), *x = malloc(sizeof(double) * (n > 0 ? n : 1));
    int ok = scratch_alloc(&W, V, F, n, mem) && cur && x;
    P.w = W.w;
    if (!ok) goto out;
    double area = 0.0;
    for (i64 q = 0; q < F; q++) {
        double a = 0.0;
        for (int c = 0; c < 4; c++) {
            i64 p0 = quads[4 * q + c], p1 = quads[4 * q + (c + 1) % 4];
            a += xy[2 * p0] * xy[2 * p1 + 1] - xy[2 * p0 + 1] * xy[2 * p1];
        }
        area += fabs(0.5 * a);
    }
    if (area == 0.0) area = 1.0;
    double eps = 1e-2 * area / (double)F, floor_ = 1e-4 * eps;
    memcpy(out, xy, sizeof(double) * 2 * V);
    memcpy(cur, xy, sizeof(double) * 2 * V);
    Key bk = quality_key(out, quads, F);
    i64 p, nx, pv;
    double e1x, e1y, e2x, e2y;
    for (i64 round = 0; round < untangle_rounds; round++) {
        double s_min = INFINITY;
        for (i64 q = 0; q < F; q++)
            for (int c = 0; c < 4; c++) {
                corner(cur, quads, q, c, &p, &nx, &pv, &e1x, &e1y, &e2x, &e2y);
                s_min = fmin(s_min, e1x * e2y - e1y * e2x);
            }
        if (s_min >= eps) break;
        double delta = sqrt(eps * (eps - s_min));
        start(&P, cur, x);
        lbfgs(&P, x, n, delta, 1.0, iters, mem, ftol, gtol, &W);
        positions(&P, x, cur);
        Key k = quality_key(cur, quads, F);
        if (better(k, bk, 1e-9)) {
            memcpy(out, cur, sizeof(double) * 2 * V);
            bk = k;
        }
    }
    memcpy(cur, out, sizeof(double) * 2 * V);
    for (i64 i = 0; i < npow; i++) {
        start(&P, cur, x);
        lbfgs(&P, x, n, floor_, powers[i], iters, mem, ftol, gtol, &W);
        positions(&P, x, cur);
        Key k = quality_key(cur, quads, F);
        if (better(k, bk, 1e-9)) {
            memcpy(out, cur, sizeof(double) * 2 * V);
            bk = k;
        }
    }
out:
    scratch_free(&W);
    free(cur); free(x);
    return ok ? 0 : -1;
}

/* energy and gradient (V, 2) at pos (tests) */
double jm_energy(const double *pos, i64 V, const i64 *quads, i64 F, double delta, double power, double *grad) {
    double *k = malloc(sizeof(double) * 4 * (F > 0 ? F : 1)), *r = malloc(sizeof(double) * 4 * (F > 0 ? F : 1)),
           *h = malloc(sizeof(double) * 4 * (F > 0 ? F : 1)), *e = malloc(sizeof(double) * 16 * (F > 0 ? F : 1));
    double f = (k && r && h && e) ? energy(pos, quads, V, F, delta, power, squarings(power), grad, k, r, h, e) : NAN;
    free(k); free(r); free(h); free(e);
    return f;
}

/* objective and gradient (n,) at the flat vector x (tests) */
double jm_objective(const double *x, i64 n, const double *base, i64 V, const i64 *quads, i64 F, const i64 *free_,
                    i64 nf, const double *sa, const double *sb, const i64 *sp, const i64 *sv, i64 S, double delta,
                    double power, double *g) {
    Problem P = {V, F, nf, S, base, quads, free_, sa, sb, sp, sv, NULL};
    Scratch W;
    int ok = scratch_alloc(&W, V, F, n, 1);
    P.w = W.w;
    double f = ok ? objective(&P, x, delta, power, squarings(power), g, &W, n) : NAN;
    scratch_free(&W);
    return f;
}

/* L-BFGS from x (n,), in place (tests) */
int jm_lbfgs(double *x, i64 n, const double *base, i64 V, const i64 *quads, i64 F, const i64 *free_, i64 nf,
             const double *sa, const double *sb, const i64 *sp, const i64 *sv, i64 S, double delta, double power,
             i64 maxiter, i64 mem, double ftol, double gtol) {
    Problem P = {V, F, nf, S, base, quads, free_, sa, sb, sp, sv, NULL};
    Scratch W;
    int rc = scratch_alloc(&W, V, F, n, mem) ? 0 : -1;
    P.w = W.w;
    if (rc == 0) lbfgs(&P, x, n, delta, power, maxiter, mem, ftol, gtol, &W);
    scratch_free(&W);
    return rc;
}

/* ------------------------------------------------------------------------------------------ */
/* Tutte: uniform weights, dense Cholesky; xy (V, 2) holds the boundary positions on entry and
   all positions on exit; returns 0, -1 out of memory, -2 not positive definite */
int jm_tutte(const i64 *quads, i64 F, i64 V, const i64 *boundary, i64 nb, double *xy) {
    char *fixed = calloc(V, 1);
    i64 *index = malloc(sizeof(i64) * V);
    double *A = calloc(V * V, sizeof(double));
    int rc = 0;
    if (!fixed || !index || !A) { rc = -1; goto out0; }
    for (i64 q = 0; q < F; q++)
        for (int c = 0; c < 4; c++) {
            i64 a = quads[4 * q + c], b = quads[4 * q + (c + 1) % 4];
            A[a * V + b] = 1.0;
            A[b * V + a] = 1.0;
        }
    for (i64 j = 0; j < nb; j++) fixed[boundary[j]] = 1;
    i64 nf = 0;
    for (i64 v = 0; v < V; v++) index[v] = fixed[v] ? -1 : nf++;
    if (nf == 0) goto out0;
    double *L = calloc(nf * nf, sizeof(double)), *rhs = calloc(2 * nf, sizeof(double));
    if (!L || !rhs) { rc = -1; goto out1; }
    for (i64 v = 0; v < V; v++) {
        i64 i = index[v];
        if (i < 0) continue;
        double deg = 0.0;
        for (i64 w = 0; w < V; w++) {
            if (A[v * V + w] == 0.0) continue;
            deg += A[v * V + w];
            if (index[w] >= 0) L[i * nf + index[w]] = -A[v * V + w];
            else { rhs[2 * i] += xy[2 * w]; rhs[2 * i + 1] += xy[2 * w + 1]; }
        }
        L[i * nf + i] = deg;
    }
    for (i64 j = 0; j < nf; j++) { /* Cholesky, lower triangle in place */
        double d = L[j * nf + j];
        for (i64 k = 0; k < j; k++) d -= L[j * nf + k] * L[j * nf + k];
        if (!(d > 0)) { rc = -2; goto out1; }
        d = sqrt(d);
        L[j * nf + j] = d;
        for (i64 i = j + 1; i < nf; i++) {
            double s = L[i * nf + j];
            for (i64 k = 0; k < j; k++) s -= L[i * nf + k] * L[j * nf + k];
            L[i * nf + j] = s / d;
        }
    }
    for (int c = 0; c < 2; c++) { /* L y = b, then L^T x = y */
        for (i64 i = 0; i < nf; i++) {
            double s = rhs[2 * i + c];
            for (i64 k = 0; k < i; k++) s -= L[i * nf + k] * rhs[2 * k + c];
            rhs[2 * i + c] = s / L[i * nf + i];
        }
        for (i64 i = nf - 1; i >= 0; i--) {
            double s = rhs[2 * i + c];
            for (i64 k = i + 1; k < nf; k++) s -= L[k * nf + i] * rhs[2 * k + c];
            rhs[2 * i + c] = s / L[i * nf + i];
        }
    }
    for (i64 v = 0; v < V; v++)
        if (index[v] >= 0) { xy[2 * v] = rhs[2 * index[v]]; xy[2 * v + 1] = rhs[2 * index[v] + 1]; }
out1:
    free(L); free(rhs);
out0:
    free(fixed); free(index); free(A);
    return rc;
}

/* ------------------------------------------------------------------------------------------ */
/* alignment DPs */

static inline i64 triple_index(const i64 *seq, i64 n, i64 j) {
    return 16 * (seq[(j + 1) % n] - 2) + 4 * (seq[j] - 2) + (seq[(j - 1 + n) % n] - 2);
}

/* best utility of every orientation: out (2n,); rotation o, then reflected rotations */
void jm_orientation_utilities(const i64 *codes, i64 m, const i64 *vals, i64 n, const double *table,
                              const double *skip, double *out) {
    i64 *seq = malloc(sizeof(i64) * n);
    double *W = malloc(sizeof(double) * n * m), *D = malloc(sizeof(double) * (n + 1));
    if (!seq || !W || !D) goto out;
    for (i64 o = 0; o < 2 * n; o++) {
        for (i64 j = 0; j < n; j++) seq[j] = o < n ? vals[(j + o) % n] : vals[n - 1 - (j + o - n) % n];
        for (i64 j = 0; j < n; j++) {
            i64 f = triple_index(seq, n, j);
            for (i64 i = 0; i < m; i++) W[j * m + i] = table[codes[i] * 64 + f];
        }
        D[0] = 0.0;
        for (i64 j = 1; j <= n; j++) D[j] = -INFINITY;
        for (i64 i = 0; i < m; i++) {
            double sk = skip[codes[i]];
            for (i64 j = n; j >= 1; j--) {
                double a = D[j] + sk, b = D[j - 1] + W[(j - 1) * m + i];
                D[j] = a > b ? a : b;
            }
            D[0] = D[0] + sk;
        }
        out[o] = D[n];
    }
out:
    free(seq); free(W); free(D);
}

/* depth-first walk over ties (n, S, m, m) from ends (e, 2); at most limit alignments into
   out (limit, n); returns the count */
static i64 walk(const char *ties, i64 n, i64 S, i64 m, const i64 *ends, i64 ne, i64 limit, i64 *out) {
    i64 count = 0;
    i64 *p = malloc(sizeof(i64) * n), *nxt = calloc(n, sizeof(i64));
    if (!p || !nxt) goto done;
    for (i64 e = 0; e < ne; e++) {
        i64 s = ends[2 * e];
        p[n - 1] = ends[2 * e + 1];
        if (n == 1) {
            if (count >= limit) goto done;
            out[count * n] = p[0];
            count++;
            continue;
        }
        i64 j = n - 1;
        nxt[j] = 0;
        while (j < n) {
            i64 found = -1;
            const char *row = ties + ((j * S + s) * m + p[j]) * m;
            for (i64 ip = nxt[j]; ip < m; ip++)
                if (row[ip]) { found = ip; break; }
            if (found < 0) { j++; continue; }
            nxt[j] = found + 1;
            p[j - 1] = found;
            if (j - 1 == 0) {
                if (count >= limit) goto done;
                memcpy(out + count * n, p, sizeof(i64) * n);
                count++;
            } else {
                j--;
                nxt[j] = 0;
            }
        }
    }
done:
    free(p); free(nxt);
    return count;
}

/* per orientation seqs (O, n): best utility util (O,), least gap cost gap (O,), and its tied
   alignments (at most limit each) into A (O * limit, n) with their orientation in own;
   returns the number of alignments, or -1 when out of memory */
i64 jm_candidates(const i64 *codes, i64 m, const i64 *seqs, i64 O, i64 n, const double *table, const double *between,
                  const double *prefix, const double *suffix, const double *gq, const double *tt, double perimeter,
                  double unit, i64 limit, double *util, double *gap, i64 *own, i64 *A) {
    i64 K = 0;
    double *E = malloc(sizeof(double) * n * m), *B = malloc(sizeof(double) * m), *Bn = malloc(sizeof(double) * m),
           *tot = malloc(sizeof(double) * m);
    i64 *starts = malloc(sizeof(i64) * m);
    if (!E || !B || !Bn || !tot || !starts) { K = -1; goto out; }
    for (i64 o = 0; o < O; o++) {
        const i64 *seq = seqs + o * n;
        util[o] = -INFINITY;
        gap[o] = 0.0;
        for (i64 j = 0; j < n; j++) {
            i64 f = triple_index(seq, n, j);
            for (i64 i = 0; i < m; i++) E[j * m + i] = table[codes[i] * 64 + f];
        }
        for (i64 i = 0; i < m; i++) B[i] = E[(n - 1) * m + i] + suffix[i];
        for (i64 j = n - 2; j >= 0; j--) {
            for (i64 i = 0; i < m; i++) {
                double mx = -INFINITY;
                for (i64 ip = 0; ip < m; ip++) {
                    double v = between[i * m + ip] + B[ip];
                    if (v > mx) mx = v;
                }
                Bn[i] = E[j * m + i] + mx;
            }
            memcpy(B, Bn, sizeof(double) * m);
        }
        double best = -INFINITY;
        for (i64 i = 0; i < m; i++) if (prefix[i] + B[i] > best) best = prefix[i] + B[i];
        if (!isfinite(best)) continue;
        i64 S = 0;
        for (i64 i = 0; i < m; i++) if (prefix[i] + B[i] == best) starts[S++] = i;
        double *U = malloc(sizeof(double) * S * m), *G = calloc(S * m, sizeof(double)),
               *Un = malloc(sizeof(double) * S * m), *Gn = malloc(sizeof(double) * S * m);
        char *ties = calloc((size_t)n * S * m * m, 1);
        i64 *ends = malloc(sizeof(i64) * 2 * S * m);
        if (!U || !G || !Un || !Gn || !ties || !ends) {
            free(U); free(G); free(Un); free(Gn); free(ties); free(ends);
            K = -1;
            goto out;
        }
        for (i64 k = 0; k < S * m; k++) U[k] = -INFINITY;
        for (i64 s = 0; s < S; s++) U[s * m + starts[s]] = prefix[starts[s]] + E[starts[s]];
        for (i64 j = 1; j < n; j++) {
            for (i64 s = 0; s < S; s++)
                for (i64 i = 0; i < m; i++) {
                    double bu = -INFINITY;
                    for (i64 ip = 0; ip < m; ip++) {
                        double t = U[s * m + ip] + between[ip * m + i] + E[j * m + i];
                        tot[ip] = t;
                        if (t > bu) bu = t;
                    }
                    double gmin = INFINITY;
                    for (i64 ip = 0; ip < m; ip++)
                        if (tot[ip] == bu) {
                            double tg = G[s * m + ip] + gq[ip * m + i];
                            if (tg < gmin) gmin = tg;
                        }
                    Un[s * m + i] = bu;
                    Gn[s * m + i] = gmin;
                    if (isfinite(gmin))
                        for (i64 ip = 0; ip < m; ip++)
                            if (tot[ip] == bu && G[s * m + ip] + gq[ip * m + i] == gmin)
                                ties[((j * S + s) * m + i) * m + ip] = 1;
                }
            memcpy(U, Un, sizeof(double) * S * m);
            memcpy(G, Gn, sizeof(double) * S * m);
        }
        double g_min = INFINITY;
        for (i64 s = 0; s < S; s++)
            for (i64 i = 0; i < m; i++) {
                double d = perimeter - tt[i] + tt[starts[s]];
                double g = G[s * m + i] + nearbyint(d * d / unit);
                G[s * m + i] = (U[s * m + i] + suffix[i] == best) ? g : INFINITY;
                if (G[s * m + i] < g_min) g_min = G[s * m + i];
            }
        i64 ne = 0;
        for (i64 s = 0; s < S; s++)
            for (i64 i = 0; i < m; i++)
                if (G[s * m + i] == g_min) { ends[2 * ne] = s; ends[2 * ne + 1] = i; ne++; }
        util[o] = best;
        gap[o] = g_min;
        i64 got = walk(ties, n, S, m, ends, ne, limit, A + K * n);
        for (i64 r = 0; r < got; r++) own[K + r] = o;
        K += got;
        free(U); free(G); free(Un); free(Gn); free(ties); free(ends);
    }
out:
    free(E); free(B); free(Bn); free(tot); free(starts);
    return K;
}

/* ------------------------------------------------------------------------------------------ */
/* per-quad quality: quality.sj_inverted's numpy operations in the same order (the same doubles) */

/* sj[f]: min over the four corners of (e1 x e2) / (|e1| |e2|) (0 where |e1| |e2| <= tiny), clipped
 * to [-1, 1] (NaN kept, as numpy's min and clip keep it); inv[f]: 1 when a corner's e1 x e2 <= 0.
 * e1 = p[next] - p, e2 = p[prev] - p; |e| = sqrt(ex * ex + ey * ey). */
void jm_sj_inverted(const double *xy, const i64 *quads, i64 F, double *sj, uint8_t *inv) {
    const double tiny = 2.2250738585072014e-308;
    for (i64 f = 0; f < F; f++) {
        const i64 *q = quads + 4 * f;
        double m = 0.0;
        int bad = 0;
        for (int c = 0; c < 4; c++) {
            const double *p = xy + 2 * q[c], *a = xy + 2 * q[(c + 1) & 3], *b = xy + 2 * q[(c + 3) & 3];
            double e1x = a[0] - p[0], e1y = a[1] - p[1], e2x = b[0] - p[0], e2y = b[1] - p[1];
            double cross = e1x * e2y - e1y * e2x;
            double l1 = e1x * e1x, l2 = e2x * e2x;
            l1 = sqrt(l1 + e1y * e1y);
            l2 = sqrt(l2 + e2y * e2y);
            double ln = l1 * l2;
            double v = ln > tiny ? cross / ln : 0.0;
            if (c == 0) m = v;
            else if (!isnan(m) && (isnan(v) || v < m)) m = v;  /* numpy's min: NaN wins */
            if (cross <= 0) bad = 1;
        }
        sj[f] = isnan(m) ? m : (m < -1.0 ? -1.0 : (m > 1.0 ? 1.0 : m));
        inv[f] = (uint8_t)bad;
    }
}

/* ------------------------------------------------------------------------------------------ */
/* spread.spread_alignment's dynamic programme: its numpy operations in the same order */

/* tt (m,): the points' arc-length parameters; ok (n, m): vertex j may take point i; starts (S,):
 * the first vertex's points. D[s][i] = 0 at starts[s], inf elsewhere; for j = 1 .. n-1:
 * D'[s][i] = min over i' of D[s][i'] + g(i, i') with g = (tt[i] - tt[i'])^2 for i' < i, inf
 * otherwise (the first i' on ties, as np.argmin; i' = 0 when every term is inf), set to inf where
 * !ok[j][i]. Then total[s][i] = D[s][i] + ((per - tt[i]) + tt[starts[s]])^2, its first minimum
 * over (s, i) in row-major order, and the walk back. Returns 0 with out (n,) filled, 1 when the
 * minimum is not finite (the caller keeps its alignment), -1 out of memory. */
int jm_spread(const double *tt, i64 m, double per, const uint8_t *ok, i64 n, const i64 *starts, i64 S, i64 *out) {
    const double inf = INFINITY;
    double *D = malloc(sizeof(double) * (size_t)(2 * S * m));
    int32_t *back = malloc(sizeof(int32_t) * (size_t)(n * S * m));
    if (!D || !back) { free(D); free(back); return -1; }
    double *Dn = D + S * m;
    for (i64 k = 0; k < S * m; k++) D[k] = inf;
    for (i64 s = 0; s < S; s++) D[s * m + starts[s]] = 0.0;
    for (i64 j = 1; j < n; j++) {
        for (i64 s = 0; s < S; s++) {
            const double *d = D + s * m;
            for (i64 i = 0; i < m; i++) {
                double best = d[0] + (0 < i ? (tt[i] - tt[0]) * (tt[i] - tt[0]) : inf);
                i64 arg = 0;
                for (i64 q = 1; q < m; q++) {
                    double v = d[q] + (q < i ? (tt[i] - tt[q]) * (tt[i] - tt[q]) : inf);
                    if (v < best) { best = v; arg = q; }
                }
                back[(j * S + s) * m + i] = (int32_t)arg;
                Dn[s * m + i] = ok[j * m + i] ? best : inf;
            }
        }
        double *tmp = D; D = Dn; Dn = tmp;
    }
    double best = inf;
    i64 flat = 0;
    for (i64 s = 0; s < S; s++)
        for (i64 i = 0; i < m; i++) {
            double c = (per - tt[i]) + tt[starts[s]];
            double v = D[s * m + i] + c * c;
            if ((s == 0 && i == 0) || v < best) { best = v; flat = s * m + i; }
        }
    int rc = 1;
    if (isfinite(best)) {
        i64 s = flat / m, i = flat % m;
        for (i64 j = n - 1; j >= 0; j--) {
            out[j] = i;
            if (j > 0) i = back[(j * S + s) * m + i];
        }
        rc = 0;
    }
    free(D < Dn ? D : Dn);
    free(back);
    return rc;
}

/* ------------------------------------------------------------------------------------------ */

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_placement",
                                    "jaxmatch's compiled placement kernels (called through ctypes)", -1, NULL};

PyMODINIT_FUNC PyInit__placement(void) { return PyModule_Create(&module); }
