/* See pg_rodas.h. */
#include "pg_rodas.h"

#include <math.h>
#include <string.h>

/* Rodas5P (OrdinaryDiffEq.jl's Rodas5PTableau): stage i's argument is y + sum_j A[i][j] k_j, its
 * right-hand side f(t + c_i h, Y_i) + h d_i dT + sum_j (C[i][j] / h) k_j; stages 7 and 8 are
 * evaluated at t + h on y + a6.k + k6 (+ k7), and y_new = that + k8 (stiffly accurate) */
static const double A[PG_RODAS_STAGES][PG_RODAS_STAGES] = {
    {0},
    {3.0},
    {2.849394379747939, 0.45842242204463923},
    {-6.954028509809101, 2.489845061869568, -10.358996098473584},
    {2.8029986275628964, 0.5072464736228206, -0.3988312541770524, -0.04721187230404641},
    {-7.502846399306121, 2.561846144803919, -11.627539656261098, -0.18268767659942256, 0.030198172008377946},
    {-7.502846399306121, 2.561846144803919, -11.627539656261098, -0.18268767659942256, 0.030198172008377946, 1.0},
    {-7.502846399306121, 2.561846144803919, -11.627539656261098, -0.18268767659942256, 0.030198172008377946, 1.0,
     1.0},
};
static const double C[PG_RODAS_STAGES][PG_RODAS_STAGES] = {
    {0},
    {-14.155112264123755},
    {-17.97296035885952, -2.859693295451294},
    {147.12150275711716, -1.41221402718213, 71.68940251302358},
    {165.43517024871676, -0.4592823456491126, 42.90938336958603, -5.961986721573306},
    {24.854864614690072, -3.0009227002832186, 47.4931110020768, 5.5814197821558125, -0.6610691825249471},
    {30.91273214028599, -3.1208243349937974, 77.79954646070892, 34.28646028294783, -19.097331116725623,
     -28.087943162872662},
    {37.80277123390563, -3.2571969029072276, 112.26918849496327, 66.9347231244047, -40.06618937091002,
     -54.66780262877968, -9.48861652309627},
};
static const double CC[PG_RODAS_STAGES] = {0.0, 0.6358126895828704, 0.4095798393397535, 0.9769306725060716,
                                          0.4288403609558664, 1.0, 1.0, 1.0};
static const double D[PG_RODAS_STAGES] = {0.21193756319429014, -0.42387512638858027, -0.3384627126235924,
                                         1.8046452872882734, 2.325825639765069, 0.0, 0.0, 0.0};
static const double H[3][PG_RODAS_STAGES] = {
    {25.948786856663858, -2.5579724845846235, 10.433815404888879, -2.3679251022685204, 0.524948541321073,
     1.1241088310450404, 0.4272876194431874, -0.17202221070155493},
    {-9.91568850695171, -0.9689944594115154, 3.0438037242978453, -24.495224566215796, 20.176138334709044,
     15.98066361424651, -6.789040303419874, -6.710236069923372},
    {11.419903575922262, 2.8879645146136994, 72.92137995996029, 80.12511834622643, -52.072871366152654,
     -59.78993625266729, -0.15582684282751913, 4.883087185713722},
};

int pg_lu_factor(double *A_, int *piv, int n)
{
    /* scaled partial pivoting: a row's candidate is measured against the row's largest entry, so
     * that a row of large coefficients (the rate of an energy, say, fed by every other state) does
     * not become the pivot of a column whose own row is well conditioned */
    double scale[PG_MAX_X];
    for (int i = 0; i < n; ++i) {
        double big = 0.0;
        for (int j = 0; j < n; ++j) big = fmax(big, fabs(A_[i * PG_MAX_X + j]));
        if (!(big > 0.0) || !isfinite(big)) return 0;
        scale[i] = 1.0 / big;
    }
    for (int k = 0; k < n; ++k) {
        int p = k;
        double big = fabs(A_[k * PG_MAX_X + k]) * scale[k];
        for (int i = k + 1; i < n; ++i) {
            double v = fabs(A_[i * PG_MAX_X + k]) * scale[i];
            if (v > big) big = v, p = i;
        }
        piv[k] = p;
        if (!(big > 0.0) || !isfinite(big)) return 0;
        if (p != k) {
            for (int j = 0; j < n; ++j) {
                double tmp = A_[k * PG_MAX_X + j];
                A_[k * PG_MAX_X + j] = A_[p * PG_MAX_X + j], A_[p * PG_MAX_X + j] = tmp;
            }
            double tmp = scale[k];
            scale[k] = scale[p], scale[p] = tmp;
        }
        double inv = 1.0 / A_[k * PG_MAX_X + k];
        for (int i = k + 1; i < n; ++i) {
            double l = A_[i * PG_MAX_X + k] * inv;
            A_[i * PG_MAX_X + k] = l;
            if (l != 0.0)
                for (int j = k + 1; j < n; ++j) A_[i * PG_MAX_X + j] -= l * A_[k * PG_MAX_X + j];
        }
    }
    return 1;
}

void pg_lu_solve(const double *LU, const int *piv, int n, double *b)
{
    /* the row swaps first (the factor's rows, multipliers included, are in their final order) */
    for (int k = 0; k < n; ++k) {
        int p = piv[k];
        if (p != k) {
            double tmp = b[k];
            b[k] = b[p], b[p] = tmp;
        }
    }
    for (int k = 0; k < n; ++k)
        for (int i = k + 1; i < n; ++i) b[i] -= LU[i * PG_MAX_X + k] * b[k];
    for (int i = n - 1; i >= 0; --i) {
        double s = b[i];
        for (int j = i + 1; j < n; ++j) s -= LU[i * PG_MAX_X + j] * b[j];
        b[i] = s / LU[i * PG_MAX_X + i];
    }
}

int pg_rodas_step(PgFun fun, void *ctx, double t, const double *y, const double *f, double h, int n,
                  const double *J, const double *dT, double *y_new, double *f_new, double *K, int *singular,
                  PgMsg *m)
{
    double W[PG_MAX_X * PG_MAX_X], Y[PG_MAX_X], r[PG_MAX_X];
    int piv[PG_MAX_X], rc;
    double inv_hg = 1.0 / (h * PG_RODAS_GAMMA);
    *singular = 0;
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) W[i * PG_MAX_X + j] = (i == j ? inv_hg : 0.0) - J[i * PG_MAX_X + j];
    if (!pg_lu_factor(W, piv, n)) {
        *singular = 1;
        for (int i = 0; i < n; ++i) y_new[i] = f_new[i] = NAN;
        memset(K, 0, sizeof(double) * PG_RODAS_STAGES * PG_MAX_X);
        return PG_OK;
    }
    for (int s = 0; s < PG_RODAS_STAGES; ++s) {
        for (int i = 0; i < n; ++i) {
            double acc = y[i];
            for (int j = 0; j < s; ++j) acc += A[s][j] * K[j * PG_MAX_X + i];
            Y[i] = acc;
        }
        if (s == 0) memcpy(r, f, sizeof(double) * (size_t)n); /* f(t, y): the caller has it */
        else if ((rc = fun(ctx, t + CC[s] * h, Y, r, m)) != PG_OK) return rc;
        for (int i = 0; i < n; ++i) {
            double acc = r[i] + h * D[s] * dT[i];
            for (int j = 0; j < s; ++j) acc += C[s][j] / h * K[j * PG_MAX_X + i];
            r[i] = acc;
        }
        pg_lu_solve(W, piv, n, r);
        memcpy(K + s * PG_MAX_X, r, sizeof(double) * (size_t)n);
    }
    for (int i = 0; i < n; ++i) y_new[i] = Y[i] + K[(PG_RODAS_STAGES - 1) * PG_MAX_X + i];
    return fun(ctx, t + h, y_new, f_new, m);
}

double pg_rodas_error_norm(const double *K, const double *y, const double *y_new, double atol, double rtol, int n)
{
    const double *k8 = K + (PG_RODAS_STAGES - 1) * PG_MAX_X;
    double acc = 0.0;
    if (n == 0) return 0.0;
    for (int i = 0; i < n; ++i) {
        double ay = fabs(y[i]), an = fabs(y_new[i]);
        double e = k8[i] / (atol + rtol * (an > ay ? an : ay));
        acc += e * e;
    }
    return sqrt(acc / n);
}

void pg_rodas_dense(const double *K, int n, double *Q)
{
    for (int r = 0; r < 3; ++r)
        for (int i = 0; i < n; ++i) {
            double acc = 0.0;
            for (int j = 0; j < PG_RODAS_STAGES; ++j) acc += H[r][j] * K[j * PG_MAX_X + i];
            Q[r * PG_MAX_X + i] = acc;
        }
}

void pg_rodas_eval(const double *Q, double t0, double h, const double *y0, const double *y1, double t, int n,
                   double *out)
{
    const double x = (t - t0) / h, x1 = 1.0 - x;
    for (int i = 0; i < n; ++i)
        out[i] = x1 * y0[i] + x * (y1[i] + x1 * (Q[i] + x * (Q[PG_MAX_X + i] + x * Q[2 * PG_MAX_X + i])));
}
