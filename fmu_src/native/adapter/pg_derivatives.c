/* pogofmu native FMUs: directional derivatives (fmi2GetDirectionalDerivative,
 * fmi3GetDirectionalDerivative) — exact, from the generated Jacobian-vector products of the flow
 * and the outputs (PgModel.flow_jvp, outputs_jvp: the model's own operations on dual numbers,
 * pogofmu.runtime.dual), at the point the outputs describe.
 *
 * Knowns: the inputs, and in model exchange the continuous states. Unknowns: the outputs, the
 * states' derivatives der(x), the states; the event counters and the time have zero derivatives. */
#include <string.h>

#include "pg_instance.h"
#include "pg_support.h"

static int state_index(const PgModel *md, const PgVar *v)
{
    if (v->role == 'x') return v->index;
    for (int i = 0; i < md->nx; ++i)
        if (strcmp(md->state_names[i], v->name) == 0) return i;
    return -1;
}

static int refuse_var(PgInstance *in, const char *fn, unsigned vr, const PgVar *v, const char *why)
{
    PgMsg m;
    pg_msg_clear(&m);
    if (!v) pg_msg_printf(&m, "%s refused: value reference %u is not a variable of %s", fn, vr, in->fmu->model->name);
    else pg_msg_printf(&m, "%s refused: %s (value reference %u) %s", fn, v->name, vr, why);
    return pg_inst_refuse(in, &m);
}

int pg_inst_directional(PgInstance *in, const unsigned *unknowns, size_t n_unknowns, const unsigned *knowns,
                        size_t n_knowns, const double *seed, double *sensitivity, const char *fn)
{
    const PgModel *md = in->fmu->model;
    PgState *st = &in->st;
    PgEngine *e = &st->sim;
    if (in->fmu->fmi == 3) {
        int rc = pg3_refresh(in);
        if (rc) return rc;
    }
    double sx[PG_MAX_X] = {0}, su[PG_MAX_U] = {0};
    int model_exchange = in->mode == 'm';
    for (size_t k = 0; k < n_knowns; ++k) {
        const PgVar *v = pg_inst_variable(in->fmu, knowns[k]);
        int i = v ? state_index(md, v) : -1;
        if (v && v->role == 'u') su[v->index] += seed[k];
        else if (v && i >= 0 && model_exchange && v->role != 'd') sx[i] += seed[k];
        else
            return refuse_var(in, fn, knowns[k], v,
                              model_exchange ? "is not a known of the directional derivatives (the continuous states "
                                               "and the inputs)"
                                             : "is not a known of the directional derivatives (the inputs)");
    }
    /* the point: before initialization the initial state, in model exchange the importer's */
    double x0[PG_MAX_X] = {0}, q0[PG_MAX_Q] = {0}, t;
    const double *x, *q, *u, *p;
    PgMsg m;
    pg_msg_clear(&m);
    if (!st->has_sim) {
        if (md->initial(st->par, x0, q0, &m) != PG_OK) {
            PgMsg out;
            pg_msg_clear(&out);
            pg_msg_printf(&out, "%s refused: no initial state with these parameters: %s", fn, m.text);
            return pg_inst_refuse(in, &out);
        }
        t = st->t_start, x = x0, q = q0, u = st->u, p = st->par;
    } else if (model_exchange) {
        t = st->me_t, x = st->me_x, q = e->q, u = e->u, p = e->p;
    } else {
        t = e->t_out, x = e->x_out, q = e->q_out, u = pg_engine_inputs_at(e, e->t_out), p = e->p;
    }
    double df[PG_MAX_X], dy[64];
    int have_df = 0, have_dy = 0;
    for (size_t k = 0; k < n_unknowns; ++k) {
        const PgVar *v = pg_inst_variable(in->fmu, unknowns[k]);
        double d = 0.0;
        if (!v || !(v->role == 'y' || v->role == 'e' || v->role == 'x' || v->role == 'd' || v->role == 't'))
            return refuse_var(in, fn, unknowns[k], v, "is not an unknown of the directional derivatives (the "
                                                      "outputs, the states and their derivatives)");
        if (v->role == 'd') {
            if (!have_df && md->flow_jvp(t, x, q, u, p, sx, su, df, &m) != PG_OK) return pg_inst_refuse(in, &m);
            have_df = 1;
            d = df[v->index];
        } else if (v->role == 'y') {
            if (!have_dy && md->outputs_jvp(t, x, q, u, p, sx, su, dy, &m) != PG_OK) return pg_inst_refuse(in, &m);
            have_dy = 1;
            d = dy[v->index];
        } else if (v->role == 'x') {
            d = sx[v->index];
        }
        sensitivity[k] = d;
    }
    return PG_ST_OK;
}
