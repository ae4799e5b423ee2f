/* The independent limit of benchmark (g), benchmarks/bench_native.py: the basic pogo stick
 * (docs/models.md "PogoStick") integrated by a hand-written
 * Dormand-Prince 5(4) in plain C. Nothing of the project's engine or generated model is used: this
 * is what a competent programmer writes by hand for this one model, the cost a native FMU is
 * measured against.
 *
 * Method: DOPRI5 with the classic coefficients (Dormand & Prince 1980; Hairer, Norsett & Wanner,
 * Solving ODEs I, Table II.5.2), first same as last (the 7th stage of an accepted step is the 1st of
 * the next); the standard error norm sqrt(mean((err_i / (abs_tol + rel_tol max(|y0_i|, |y1_i|)))^2))
 * of the embedded 4th-order difference; the standard controller h_new = h min(10, max(0.2,
 * 0.9 err^(-1/5))) (no growth right after a rejection), steps at most max_step; Hairer's starting
 * step at the start and after every event. Events are located on the 4th-order continuous extension
 * of DOPRI5 (dopri5.f's CONTD5) by the Illinois variant of regula falsi on the guard, to a few ulps
 * of the time; the mode switches there and the integration restarts from the jumped state. The
 * communication grid is served by the same interpolant (the step is never shortened for a grid
 * point), and y is recorded at every grid point.
 *
 * Model (F_ext = 0): states x = [xbar, xdot, y, ydot, z], mode s (0 flight, 1 contact),
 *   flight:  xbar' = xdot, xdot' = 0, y' = ydot, ydot' = -g, z' = ydot - xdot
 *   contact: r = k (xbar - x_i) + c xdot, a = -g - r/m;
 *            xbar' = xdot, xdot' = a, y' = ydot, ydot' = a, z' = 0
 *   touchdown (flight, z falling): s <- 1, xdot <- ydot, z <- 0
 *   liftoff (contact, xbar - x_i rising): s <- 0, xdot <- 0, xbar <- x_i, z <- 0
 *
 *   dopri5_pogostick [STOP [STEP [REPEAT]]] [name=value ...]
 *
 * names: m k c x_i g xbar_0 xdot_0 y_0 ydot_0 z_0 rel_tol abs_tol max_step (the FMU's defaults
 * otherwise; the values are read at run time, so the compiler cannot fold them). Prints the events
 * (kind, time), a checksum of the recorded y, and one summary line with the CPU time
 * (CLOCK_PROCESS_CPUTIME_ID) of the best of REPEAT runs of the whole loop, the same clock as
 * engine_loop.c and the C host, and that time per communication step in us. */
#define _POSIX_C_SOURCE 199309L /* clock_gettime under -std=c99 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#ifdef FMU_DUTIES
/* Built with -DFMU_DUTIES (for information, benchmarks/bench_native.py --duties): the same program doing
 * what the FMU must do besides, to show where the rest of its cost lies: the FMU's seven states (the
 * leg's work W_leg' = r xdot in contact and the external force's W_ext' = F ydot = 0, in the error
 * norm as the FMU has them), and at every grid point every state interpolated and the model's 11
 * outputs computed and checked to be finite (the FMU reports a non-finite output from the step
 * that produced it), y recorded. Not the limit: the target is judged against the plain program. */
#define NX 7
#else
#define NX 5
#endif
#define MAX_EVENTS 1000

/* Butcher tableau of DOPRI5 */
#define C2 (1.0 / 5.0)
#define C3 (3.0 / 10.0)
#define C4 (4.0 / 5.0)
#define C5 (8.0 / 9.0)
#define A21 (1.0 / 5.0)
#define A31 (3.0 / 40.0)
#define A32 (9.0 / 40.0)
#define A41 (44.0 / 45.0)
#define A42 (-56.0 / 15.0)
#define A43 (32.0 / 9.0)
#define A51 (19372.0 / 6561.0)
#define A52 (-25360.0 / 2187.0)
#define A53 (64448.0 / 6561.0)
#define A54 (-212.0 / 729.0)
#define A61 (9017.0 / 3168.0)
#define A62 (-355.0 / 33.0)
#define A63 (46732.0 / 5247.0)
#define A64 (49.0 / 176.0)
#define A65 (-5103.0 / 18656.0)
#define A71 (35.0 / 384.0)
#define A73 (500.0 / 1113.0)
#define A74 (125.0 / 192.0)
#define A75 (-2187.0 / 6784.0)
#define A76 (11.0 / 84.0)
/* error coefficients: 5th-order weights less the embedded 4th-order ones */
#define E1 (71.0 / 57600.0)
#define E3 (-71.0 / 16695.0)
#define E4 (71.0 / 1920.0)
#define E5 (-17253.0 / 339200.0)
#define E6 (22.0 / 525.0)
#define E7 (-1.0 / 40.0)
/* the dense output (Hairer's dopri5.f) */
#define D1 (-12715105075.0 / 11282082432.0)
#define D3 (87487479700.0 / 32700410799.0)
#define D4 (-10690763975.0 / 1880347072.0)
#define D5 (701980252875.0 / 199316789632.0)
#define D6 (-1453857185.0 / 822651844.0)
#define D7 (69997945.0 / 29380423.0)

#define SAFETY 0.9
#define FAC_MIN 0.2
#define FAC_MAX 10.0

typedef struct {
    double m, k, c, x_i, g, x0[NX], rtol, atol, hmax;
} Par;

typedef struct {
    int kind; /* 1 touchdown, 2 liftoff */
    double t;
} Event;

static inline void flow(int s, const Par *p, const double *x, double *f)
{
    if (s == 0) {
        f[0] = x[1];
        f[1] = 0.0;
        f[2] = x[3];
        f[3] = -p->g;
        f[4] = x[3] - x[1];
#ifdef FMU_DUTIES
        f[5] = 0.0;
        f[6] = 0.0;
#endif
    } else {
        double r = p->k * (x[0] - p->x_i) + p->c * x[1], a = -p->g - r / p->m;
        f[0] = x[1];
        f[1] = a;
        f[2] = x[3];
        f[3] = a;
        f[4] = 0.0;
#ifdef FMU_DUTIES
        f[5] = r * x[1];
        f[6] = 0.0;
#endif
    }
}

/* the guard of the mode's one event, signed so that the event is its fall through zero */
static inline double guard(int s, const Par *p, const double *x)
{
    return s == 0 ? x[4] : p->x_i - x[0];
}

static double rms_scaled(const double *v, const double *sc)
{
    double acc = 0.0;
    for (int i = 0; i < NX; ++i) acc += (v[i] / sc[i]) * (v[i] / sc[i]);
    return sqrt(acc / NX);
}

/* Hairer's starting step (Solving ODEs I, II.4), order 5 */
static double initial_step(int s, const Par *p, const double *x, const double *f)
{
    double sc[NX], x1[NX], f1[NX], d[NX];
    for (int i = 0; i < NX; ++i) sc[i] = p->atol + p->rtol * fabs(x[i]);
    double d0 = rms_scaled(x, sc), d1 = rms_scaled(f, sc);
    double h0 = (d0 < 1e-5 || d1 < 1e-5) ? 1e-6 : 0.01 * d0 / d1;
    if (h0 > p->hmax) h0 = p->hmax;
    for (int i = 0; i < NX; ++i) x1[i] = x[i] + h0 * f[i];
    flow(s, p, x1, f1);
    for (int i = 0; i < NX; ++i) d[i] = f1[i] - f[i];
    double d2 = rms_scaled(d, sc) / h0, dm = d1 > d2 ? d1 : d2;
    double h1 = dm <= 1e-15 ? (h0 * 1e-3 > 1e-6 ? h0 * 1e-3 : 1e-6) : pow(0.01 / dm, 1.0 / 5.0);
    double h = 100.0 * h0 < h1 ? 100.0 * h0 : h1;
    return h < p->hmax ? h : p->hmax;
}

/* the continuous extension of component i over the step [t, t + h]: r[0..4] */
static inline void dense_coeffs(int i, double h, const double *x0, const double *x1, const double K[7][NX],
                                double *r)
{
    double dx = x1[i] - x0[i], bspl = h * K[0][i] - dx;
    r[0] = x0[i];
    r[1] = dx;
    r[2] = bspl;
    r[3] = dx - h * K[6][i] - bspl;
    r[4] = h * (D1 * K[0][i] + D3 * K[2][i] + D4 * K[3][i] + D5 * K[4][i] + D6 * K[5][i] + D7 * K[6][i]);
}

static inline double dense_at(const double *r, double th)
{
    double th1 = 1.0 - th;
    return r[0] + th * (r[1] + th1 * (r[2] + th * (r[3] + th1 * r[4])));
}

/* the coefficients of the continuous extension a step's grid points are served from, once a step:
 * y's (ry[0..4]); with FMU_DUTIES every state's (ry[5 i .. 5 i + 4]) */
static inline void serving_coeffs(double h, const double *x0, const double *x1, const double K[7][NX], double *ry)
{
#ifdef FMU_DUTIES
    for (int i = 0; i < NX; ++i) dense_coeffs(i, h, x0, x1, K, ry + 5 * i);
#else
    dense_coeffs(2, h, x0, x1, K, ry);
#endif
}

/* the grid point at theta: y (the plain program); with FMU_DUTIES every state and the 11 outputs,
 * their finiteness checked (a non-finite one: -1) */
static inline int serve(int s, const Par *p, const double *ry, double th, double *y)
{
#ifdef FMU_DUTIES
    double xs[NX], out[11];
    for (int i = 0; i < NX; ++i) xs[i] = dense_at(ry + 5 * i, th);
    double xd = xs[0] - p->x_i;
    out[0] = xs[0], out[1] = xs[1], out[2] = xs[2], out[3] = xs[3], out[4] = xs[4], out[5] = xd;
    out[6] = s ? p->k * xd + p->c * xs[1] : 0.0;
    out[7] = s;
    out[8] = 0.5 * p->m * xs[3] * xs[3] + p->m * p->g * xs[2];
    out[9] = xs[5], out[10] = xs[6];
    double acc = 0.0;
    for (int i = 0; i < 11; ++i) acc += out[i];
    *y = out[2];
    return isfinite(acc) ? 0 : -1;
#else
    (void)s, (void)p;
    *y = dense_at(ry, th);
    return 0;
#endif
}

/* the guard on the interpolant at theta */
static inline double guard_at(int s, const Par *p, const double *rg, double th)
{
    double v = dense_at(rg, th);
    return s == 0 ? v : p->x_i - v;
}

/* One run over [0, stop]: y at the n + 1 grid points into rec, the events into ev, the steps
 * taken into steps[0] (accepted) and steps[1] (rejected); the number of events */
static int run(const Par *p, double stop, double H, long n, double *rec, Event *ev, long *steps)
{
    double x[NX], x1[NX], K[7][NX], xs[NX], sc, err, ry[5 * NX], rg[5];
    int s = p->x0[4] > 0.0 ? 0 : 1, n_ev = 0, rejected = 0;
    double t = 0.0;
    memcpy(x, p->x0, sizeof x);
    flow(s, p, x, K[0]);
    double h = initial_step(s, p, x, K[0]);
    rec[0] = x[2];
    long k = 1, n_acc = 0, n_rej = 0;
    double tk = H; /* the next grid point */
    while (k <= n) {
        if (h > p->hmax) h = p->hmax;
        if (t + h > stop) h = stop - t;
        /* the stages */
        for (int i = 0; i < NX; ++i) xs[i] = x[i] + h * A21 * K[0][i];
        flow(s, p, xs, K[1]);
        for (int i = 0; i < NX; ++i) xs[i] = x[i] + h * (A31 * K[0][i] + A32 * K[1][i]);
        flow(s, p, xs, K[2]);
        for (int i = 0; i < NX; ++i) xs[i] = x[i] + h * (A41 * K[0][i] + A42 * K[1][i] + A43 * K[2][i]);
        flow(s, p, xs, K[3]);
        for (int i = 0; i < NX; ++i)
            xs[i] = x[i] + h * (A51 * K[0][i] + A52 * K[1][i] + A53 * K[2][i] + A54 * K[3][i]);
        flow(s, p, xs, K[4]);
        for (int i = 0; i < NX; ++i)
            xs[i] = x[i] + h * (A61 * K[0][i] + A62 * K[1][i] + A63 * K[2][i] + A64 * K[3][i] + A65 * K[4][i]);
        flow(s, p, xs, K[5]);
        for (int i = 0; i < NX; ++i)
            x1[i] = x[i] + h * (A71 * K[0][i] + A73 * K[2][i] + A74 * K[3][i] + A75 * K[4][i] + A76 * K[5][i]);
        flow(s, p, x1, K[6]);
        /* the error */
        err = 0.0;
        for (int i = 0; i < NX; ++i) {
            double e = h * (E1 * K[0][i] + E3 * K[2][i] + E4 * K[3][i] + E5 * K[4][i] + E6 * K[5][i] + E7 * K[6][i]);
            double a0 = fabs(x[i]), a1 = fabs(x1[i]);
            sc = p->atol + p->rtol * (a0 > a1 ? a0 : a1);
            err += (e / sc) * (e / sc);
        }
        err = sqrt(err / NX);
        double fac = err == 0.0 ? FAC_MAX : SAFETY * pow(err, -0.2);
        if (!(err <= 1.0)) { /* rejected */
            h *= fac > FAC_MIN ? fac : FAC_MIN;
            rejected = 1;
            ++n_rej;
            continue;
        }
        if (fac > FAC_MAX) fac = FAC_MAX;
        if (rejected && fac > 1.0) fac = 1.0;
        rejected = 0;
        ++n_acc;
        double t1 = t + h, h_next = h * fac;
        /* an event in this step? */
        double g0 = guard(s, p, x), g1 = guard(s, p, x1);
        if (g0 > 0.0 && g1 <= 0.0) {
            int gi = s == 0 ? 4 : 0;
            dense_coeffs(gi, h, x, x1, K, rg);
            /* Illinois regula falsi on theta in [0, 1]: ga > 0 >= gb */
            double a = 0.0, b = 1.0, ga = g0, gb = g1;
            int side = 0;
            double tol = 4.0 * 2.220446049250313e-16 * (fabs(t1) > 1.0 ? fabs(t1) : 1.0) / h;
            while (b - a > tol) {
                double c = b - gb * (b - a) / (gb - ga);
                if (!(c > a && c < b)) c = 0.5 * (a + b);
                double gc = guard_at(s, p, rg, c);
                if (gc > 0.0) {
                    a = c, ga = gc;
                    if (side == -1) gb *= 0.5;
                    side = -1;
                } else {
                    b = c, gb = gc;
                    if (gc == 0.0) break;
                    if (side == 1) ga *= 0.5;
                    side = 1;
                }
            }
            double te = t + b * h;
            /* the grid up to the event from this step's interpolant */
            if (k <= n && tk < te) {
                serving_coeffs(h, x, x1, K, ry);
                while (k <= n && tk < te) {
                    if (serve(s, p, ry, (tk - t) / h, &rec[k])) return -1;
                    tk = (double)(++k) * H;
                }
            }
            /* the state at the event, the jump */
            double xe[NX], r[5];
            for (int i = 0; i < NX; ++i) {
                dense_coeffs(i, h, x, x1, K, r);
                xe[i] = dense_at(r, b);
            }
            if (s == 0) {
                xe[1] = xe[3], xe[4] = 0.0;
            } else {
                xe[0] = p->x_i, xe[1] = 0.0, xe[4] = 0.0;
            }
            if (n_ev < MAX_EVENTS) ev[n_ev].kind = s == 0 ? 1 : 2, ev[n_ev].t = te;
            ++n_ev;
            s = 1 - s;
            t = te;
            memcpy(x, xe, sizeof x);
            flow(s, p, x, K[0]);
            h = initial_step(s, p, x, K[0]);
            continue;
        }
        /* the grid points in (t, t1] */
        if (k <= n && tk <= t1) {
            serving_coeffs(h, x, x1, K, ry);
            while (k <= n && tk <= t1) {
                if (serve(s, p, ry, (tk - t) / h, &rec[k])) return -1;
                tk = (double)(++k) * H;
            }
        }
        t = t1;
        memcpy(x, x1, sizeof x);
        memcpy(K[0], K[6], sizeof K[0]); /* FSAL */
        h = h_next;
        if (t >= stop && k <= n) { /* the last grid point at stop itself */
            while (k <= n) rec[k++] = x[2];
        }
    }
    steps[0] = n_acc, steps[1] = n_rej;
    return n_ev;
}

int main(int argc, char **argv)
{
    /* the FMU's defaults, through volatile: read at run time like the FMU's parameters */
    volatile double dflt[] = {1.0, 100.0, 0.5, 1.0, 9.81, 1.0, 0.0, 1.5, 0.0, 0.5, 1e-6, 1e-12, 0.01};
    static const char *names[] = {"m", "k", "c", "x_i", "g", "xbar_0", "xdot_0", "y_0", "ydot_0", "z_0",
                                  "rel_tol", "abs_tol", "max_step"};
    double v[13];
    for (int i = 0; i < 13; ++i) v[i] = dflt[i];
    double stop = 10.0, H = 1e-3;
    int repeat = 20, pos = 0;
    for (int a = 1; a < argc; ++a) {
        char *eq = strchr(argv[a], '=');
        if (!eq) {
            if (pos == 0) stop = atof(argv[a]);
            else if (pos == 1) H = atof(argv[a]);
            else if (pos == 2) repeat = atoi(argv[a]);
            ++pos;
            continue;
        }
        int found = 0;
        for (int i = 0; i < 13; ++i)
            if ((size_t)(eq - argv[a]) == strlen(names[i]) && !strncmp(argv[a], names[i], strlen(names[i])))
                v[i] = atof(eq + 1), found = 1;
        if (!found) { fprintf(stderr, "unknown parameter %s\n", argv[a]); return 2; }
    }
    Par p = {v[0], v[1], v[2], v[3], v[4], {v[5], v[6], v[7], v[8], v[9]}, v[10], v[11], v[12]}; /* (W_leg, W_ext: 0) */
    if (!(stop > 0.0) || !(H > 0.0) || repeat < 1) { fprintf(stderr, "bad STOP, STEP or REPEAT\n"); return 2; }
    long n = (long)(stop / H + 0.5);
    double *rec = malloc(sizeof(double) * (size_t)(n + 1));
    Event ev[MAX_EVENTS];
    if (!rec) return 2;
    double best = INFINITY, checksum = 0.0;
    int n_ev = 0;
    long steps[2] = {0, 0};
    for (int r = 0; r < repeat; ++r) {
        struct timespec c0, c1;
        clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &c0);
        n_ev = run(&p, stop, H, n, rec, ev, steps);
        if (n_ev < 0) { fprintf(stderr, "an output that is not finite\n"); return 1; }
        clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &c1);
        double dt = (double)(c1.tv_sec - c0.tv_sec) + 1e-9 * (double)(c1.tv_nsec - c0.tv_nsec);
        if (dt < best) best = dt;
        double sum = 0.0;
        for (long k = 0; k <= n; ++k) sum += rec[k];
        if (r > 0 && sum != checksum) { fprintf(stderr, "runs differ\n"); return 1; }
        checksum = sum;
    }
    for (int i = 0; i < n_ev && i < MAX_EVENTS; ++i)
        printf("event %d %s t = %.17g\n", i + 1, ev[i].kind == 1 ? "touchdown" : "liftoff", ev[i].t);
    printf("y checksum %.17g, y(%g) = %.17g\n", checksum, n * H, rec[n]);
    printf("%ld steps accepted, %ld rejected\n", steps[0], steps[1]);
    printf("recorded %ld points, %d events, loop cpu %.9f s (best of %d), %.4f us per step\n", n + 1, n_ev, best,
           repeat, best / (double)n * 1e6);
    free(rec);
    return 0;
}
