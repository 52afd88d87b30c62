/* duffid adaptive controller: portable C99 core (see duffid_controller.h). Every
 * floating-point expression mirrors duffid.control.adaptive.AdaptiveController operation for
 * operation; keep them in step. */
#include "duffid_controller.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#define DT_RTOL 1e-9
#define SWITCH_RTOL 1e-6
#define PI 3.14159265358979323846

static void message(char *msg, size_t size, const char *text, const char *name, double value)
{
    if (msg == NULL || size == 0) return;
    snprintf(msg, size, text, name, value);
}

static int bad(char *msg, size_t size, const char *name, const char *rule, double value)
{
    char text[160];
    snprintf(text, sizeof text, "parameter %%s %s, got %%.17g", rule);
    message(msg, size, text, name, value);
    return DUFFID_CTRL_ERR_CONFIG;
}

/* The checks of the parameter table (duffid_ctrl_params.h, generated from
 * duffid.control.settings.PARAMETERS): a REAL is finite and obeys its rule, an INT is in its
 * range; then the nominal values (finite, masses positive) and the excitation limit. */
#define CTRL_RULE_FINITE 0
#define CTRL_RULE_POSITIVE 1
#define CTRL_RULE_NON_NEGATIVE 2

static int check_real(const char *name, double v, int rule, const char *text, char *msg, size_t size)
{
    if (!isfinite(v)) return bad(msg, size, name, "must be finite", v);
    if ((rule == CTRL_RULE_POSITIVE && !(v > 0.0)) || (rule == CTRL_RULE_NON_NEGATIVE && !(v >= 0.0)))
        return bad(msg, size, name, text, v);
    return DUFFID_CTRL_OK;
}

static int check_int(const char *name, int v, int lo, int hi, const char *text, char *msg, size_t size)
{
    if (v < lo || v > hi) return bad(msg, size, name, text, (double)v);
    return DUFFID_CTRL_OK;
}

int duffid_ctrl_check(const duffid_ctrl_config *cfg, char *msg, size_t msg_size)
{
    static const char *const names1[] = {"m_nominal", "b_nominal", "k_nominal", "kp_nominal"};
    static const char *const names2[] = {"m1_nominal", "b1_nominal", "k1_nominal", "kp1_nominal",
                                         "b2_nominal", "k2_nominal", "kp2_nominal", "m2_nominal"};
    int i, n, rc;
    if (cfg->dofs != 1 && cfg->dofs != 2) return bad(msg, msg_size, "dofs", "must be 1 or 2", cfg->dofs);
#define CTRL_CHECK_REAL(field, name, rule, lo, hi, text) \
    rc = check_real(#name, cfg->field, CTRL_RULE_##rule, text, msg, msg_size);
#define CTRL_CHECK_INT(field, name, rule, lo, hi, text) rc = check_int(#name, cfg->field, lo, hi, text, msg, msg_size);
#define CTRL_CHECK_BOOL(field, name, rule, lo, hi, text) rc = DUFFID_CTRL_OK;
#define CTRL_CHECK(kind, field, NAME, name, rule, lo, hi, text) \
    CTRL_CHECK_##kind(field, name, rule, lo, hi, text) if (rc != DUFFID_CTRL_OK) return rc;
    DUFFID_CTRL_PARAMETERS(CTRL_CHECK)
#undef CTRL_CHECK
#undef CTRL_CHECK_BOOL
#undef CTRL_CHECK_INT
#undef CTRL_CHECK_REAL
    n = cfg->dofs == 1 ? 4 : 8;
    for (i = 0; i < n; i++) {
        const char *name = cfg->dofs == 1 ? names1[i] : names2[i];
        if (!isfinite(cfg->nominal[i])) return bad(msg, msg_size, name, "must be finite", cfg->nominal[i]);
        if (name[0] == 'm' && !(cfg->nominal[i] > 0.0))
            return bad(msg, msg_size, name, "must be positive", cfg->nominal[i]);
    }
    if (fabs(cfg->excitation_amplitude) > cfg->force_limit) {
        if (msg != NULL && msg_size > 0)
            snprintf(msg, msg_size, "excitation_amplitude %.17g exceeds force_limit %.17g",
                     cfg->excitation_amplitude, cfg->force_limit);
        return DUFFID_CTRL_ERR_CONFIG;
    }
    return DUFFID_CTRL_OK;
}

/* Weights of the derivative at the newest sample of the least-squares quadratic through
 * n samples (tau_j = -j); all sums and cofactors are integers below 2^53 for n <= 64. */
static void diff_coefficients(int n, double *c)
{
    double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0, s4 = 0.0, det, c0, c1, c2;
    int j;
    for (j = 0; j < n; j++) {
        double tau = -(double)j;
        s0 += 1.0;
        s1 += tau;
        s2 += tau * tau;
        s3 += tau * tau * tau;
        s4 += tau * tau * tau * tau;
    }
    det = s0 * (s2 * s4 - s3 * s3) - s1 * (s1 * s4 - s3 * s2) + s2 * (s1 * s3 - s2 * s2);
    c0 = -(s1 * s4 - s3 * s2);
    c1 = s0 * s4 - s2 * s2;
    c2 = -(s0 * s3 - s1 * s2);
    for (j = 0; j < n; j++) c[j] = (c0 + c1 * (-(double)j) + c2 * ((double)j * (double)j)) / det;
}

static double excitation(const duffid_ctrl *ctrl, double t)
{
    const duffid_ctrl_config *p = &ctrl->cfg;
    double tau, f0, f1, T, phi;
    if (p->excitation == 0) return p->excitation_amplitude;
    tau = t - ctrl->t0;
    f0 = p->chirp_f0;
    f1 = p->chirp_f1;
    T = p->chirp_duration;
    if (tau <= T)
        phi = f0 * tau + 0.5 * (f1 - f0) / T * (tau * tau);
    else
        phi = f0 * T + 0.5 * (f1 - f0) * T + f1 * (tau - T);
    return p->excitation_amplitude * sin(2.0 * PI * phi);
}

/* Restoring force on m1 (elements 1 and 2) into *g, force of element 2 into *f2. */
static void coupling(int dofs, const double *th, const double *x, const double *v, double *g, double *f2)
{
    double f1 = th[1] * v[0] + th[2] * x[0] + th[3] * (x[0] * x[0] * x[0]);
    if (dofs == 1) {
        *g = f1;
        *f2 = 0.0;
    } else {
        double d = x[0] - x[1];
        *f2 = th[4] * (v[0] - v[1]) + th[5] * d + th[6] * (d * d * d);
        *g = f1 + *f2;
    }
}

/* y = (x[0..n-1], v[0..n-1]) -> dy. */
static void deriv(int dofs, const double *th, double f, const double *y, double *dy)
{
    double g, f2;
    coupling(dofs, th, y, y + dofs, &g, &f2);
    if (dofs == 1) {
        dy[0] = y[1];
        dy[1] = (f - g) / th[0];
    } else {
        dy[0] = y[2];
        dy[1] = y[3];
        dy[2] = (f - g) / th[0];
        dy[3] = f2 / th[7];
    }
}

static void predict(duffid_ctrl *ctrl, double f, double h)
{
    int n = ctrl->cfg.dofs, m = 2 * n, i;
    double y[4], yt[4], k1[4], k2[4], k3[4], k4[4], h2 = 0.5 * h, h6 = h / 6.0;
    for (i = 0; i < n; i++) {
        y[i] = ctrl->xh[i];
        y[n + i] = ctrl->vh[i];
    }
    deriv(n, ctrl->theta, f, y, k1);
    for (i = 0; i < m; i++) yt[i] = y[i] + h2 * k1[i];
    deriv(n, ctrl->theta, f, yt, k2);
    for (i = 0; i < m; i++) yt[i] = y[i] + h2 * k2[i];
    deriv(n, ctrl->theta, f, yt, k3);
    for (i = 0; i < m; i++) yt[i] = y[i] + h * k3[i];
    deriv(n, ctrl->theta, f, yt, k4);
    for (i = 0; i < m; i++) y[i] = y[i] + h6 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    for (i = 0; i < n; i++) {
        ctrl->xh[i] = y[i];
        ctrl->vh[i] = y[n + i];
    }
}

static void ref_deriv(const duffid_ctrl *ctrl, double r, const double *y, double *dy)
{
    dy[0] = y[1];
    dy[1] = y[2];
    dy[2] = ctrl->w3 * (r - y[0]) - ctrl->w2 * y[1] - ctrl->w1 * y[2];
}

/* One RK4 step of the reference model from y (in place) with r held; r = 0: the
 * homogeneous system of the transient z. */
static void advance_reference(const duffid_ctrl *ctrl, double *y, double r, double h)
{
    double yt[3], k1[3], k2[3], k3[3], k4[3], h2 = 0.5 * h, h6 = h / 6.0;
    int i;
    ref_deriv(ctrl, r, y, k1);
    for (i = 0; i < 3; i++) yt[i] = y[i] + h2 * k1[i];
    ref_deriv(ctrl, r, yt, k2);
    for (i = 0; i < 3; i++) yt[i] = y[i] + h2 * k2[i];
    ref_deriv(ctrl, r, yt, k3);
    for (i = 0; i < 3; i++) yt[i] = y[i] + h * k3[i];
    ref_deriv(ctrl, r, yt, k4);
    for (i = 0; i < 3; i++) y[i] = y[i] + h6 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
}

/* (r, r', r'') at t_{k+1} from the samples at t_k (second-order Taylor). */
static void predicted_reference(const duffid_ctrl_input *in, double h, double *rp)
{
    rp[0] = in->r + h * in->r_dot + 0.5 * (h * h) * in->r_ddot;
    rp[1] = in->r_dot + h * in->r_ddot;
    rp[2] = in->r_ddot;
}

static double derivative(const duffid_ctrl *ctrl, int dof, double h)
{
    int n = ctrl->cfg.differentiator_samples, j;
    double acc = 0.0;
    for (j = 0; j < n; j++) acc += ctrl->c[j] * ctrl->buf[dof][(ctrl->head - j + n) % n];
    return acc / h;
}

static void law(duffid_ctrl *ctrl)
{
    const duffid_ctrl_config *p = &ctrl->cfg;
    double w, g, f2, f, limit = p->force_limit;
    w = ctrl->ref[2] - p->K[0] * (ctrl->xh[0] - ctrl->ref[0]) - p->K[1] * (ctrl->vh[0] - ctrl->ref[1]);
    coupling(p->dofs, ctrl->theta, ctrl->xh, ctrl->vh, &g, &f2);
    f = ctrl->theta[0] * w + g;
    ctrl->saturated = f > limit || f < -limit;
    ctrl->f = f > limit ? limit : (f < -limit ? -limit : f);
}

static int usable(const duffid_ctrl *ctrl, const duffid_ctrl_input *in)
{
    int i;
    if (!in->identified) return 0;
    for (i = 0; i < ctrl->n_params; i++)
        if (!isfinite(in->estimate[i])) return 0;
    return in->estimate[0] > 0.0 && (ctrl->cfg.dofs == 1 || in->estimate[7] > 0.0);
}

void duffid_ctrl_outputs(const duffid_ctrl *ctrl, duffid_ctrl_output *out)
{
    int i;
    out->f = ctrl->f;
    out->f_sample = ctrl->f_sample;
    out->phase = ctrl->phase;
    out->x_ref = ctrl->ref[0];
    out->v_hat[0] = ctrl->vh[0];
    out->v_hat[1] = ctrl->vh[1]; /* NaN for 1 DOF */
    out->saturated = ctrl->saturated;
    out->switch_time = ctrl->switch_time;
    for (i = 0; i < DUFFID_CTRL_MAX_PARAMS; i++) out->used[i] = ctrl->theta[i]; /* NaN beyond n_params */
}

int duffid_ctrl_init(duffid_ctrl *ctrl, const duffid_ctrl_config *cfg, double t0, duffid_ctrl_output *out,
                     char *msg, size_t msg_size)
{
    int rc = duffid_ctrl_check(cfg, msg, msg_size), i;
    double wr;
    if (rc != DUFFID_CTRL_OK) return rc;
    memset(ctrl, 0, sizeof *ctrl);
    ctrl->cfg = *cfg;
    ctrl->n_params = cfg->dofs == 1 ? 4 : 8;
    diff_coefficients(cfg->differentiator_samples, ctrl->c);
    wr = cfg->reference_bandwidth;
    ctrl->w3 = wr * wr * wr;
    ctrl->w2 = 3.0 * wr * wr;
    ctrl->w1 = 3.0 * wr;
    ctrl->t0 = t0;
    ctrl->head = cfg->differentiator_samples - 1;
    ctrl->count = 0;
    ctrl->have_ref = 0;
    ctrl->settle_start = 0.0;
    ctrl->phase = 0;
    for (i = 0; i < DUFFID_CTRL_MAX_PARAMS; i++) ctrl->theta[i] = NAN;
    for (i = 0; i < 2; i++) ctrl->xh[i] = ctrl->vh[i] = NAN;
    for (i = 0; i < 3; i++) ctrl->ref[i] = ctrl->z[i] = NAN;
    ctrl->switch_time = NAN;
    ctrl->saturated = 0;
    ctrl->f = excitation(ctrl, t0);
    ctrl->f_sample = ctrl->f;
    ctrl->initialized = 1;
    if (out != NULL) duffid_ctrl_outputs(ctrl, out);
    return DUFFID_CTRL_OK;
}

/* ------------------------------------------------------------------ state check */

static int same_bits(double a, double b)
{
    return memcmp(&a, &b, sizeof a) == 0;
}

/* Nonzero when the n values are all finite (nan_rest: and the rest up to max all NaN). */
static int all_finite(const double *v, int n, int max, int nan_rest)
{
    int i;
    for (i = 0; i < max; i++) {
        if (i < n ? !isfinite(v[i]) : (nan_rest && !isnan(v[i]))) return 0;
    }
    return 1;
}

static int all_nan(const double *v, int n)
{
    int i;
    for (i = 0; i < n; i++)
        if (!isnan(v[i])) return 0;
    return 1;
}

static int force_ok(double f, double limit)
{
    return isfinite(f) && fabs(f) <= limit;
}

/* The first field whose value the controller cannot have computed (NULL: none): forces within
 * force_limit, measured positions and settling estimates finite, and per phase the law's
 * values finite (control) or not yet set (NaN: excitation). Also what a step must leave. */
static const char *bad_values(const duffid_ctrl *ctrl)
{
    const duffid_ctrl_config *p = &ctrl->cfg;
    const int n = p->dofs, size = p->differentiator_samples, np = ctrl->n_params;
    int i;
    for (i = 0; i < n; i++)
        if (!all_finite(ctrl->buf[i], size, size, 0)) return "buf (measured positions)";
    if (ctrl->have_ref &&
        !(all_finite(ctrl->p_ref, np, np, 0) && ctrl->p_ref[0] > 0.0 && (n == 1 || ctrl->p_ref[7] > 0.0)))
        return "p_ref (estimates settling)";
    if (!isfinite(ctrl->settle_start)) return "settle_start";
    if (!force_ok(ctrl->f, p->force_limit)) return "f (force)";
    if (!force_ok(ctrl->f_sample, p->force_limit)) return "f_sample (force sample)";
    if (ctrl->phase == 0) { /* excitation: nothing of the control law yet */
        if (!all_nan(ctrl->theta, DUFFID_CTRL_MAX_PARAMS)) return "theta (parameters of the law)";
        if (!all_nan(ctrl->xh, 2) || !all_nan(ctrl->vh, 2)) return "xh, vh (observer)";
        if (!all_nan(ctrl->ref, 3) || !all_nan(ctrl->z, 3)) return "ref, z (reference model)";
        if (!isnan(ctrl->switch_time)) return "switch_time";
        if (ctrl->saturated) return "saturated";
        return NULL;
    }
    if (!(all_finite(ctrl->theta, np, DUFFID_CTRL_MAX_PARAMS, 1) && ctrl->theta[0] > 0.0 &&
          (n == 1 || ctrl->theta[7] > 0.0)))
        return "theta (parameters of the law)";
    if (!all_finite(ctrl->xh, n, 2, 1) || !all_finite(ctrl->vh, n, 2, 1)) return "xh, vh (observer)";
    if (!all_finite(ctrl->ref, 3, 3, 0)) return "ref (reference model)";
    if (p->reference_model == 1 ? !all_finite(ctrl->z, 3, 3, 0) : !all_nan(ctrl->z, 3)) return "z (transient)";
    if (!isfinite(ctrl->switch_time)) return "switch_time";
    return NULL;
}

int duffid_ctrl_step(duffid_ctrl *ctrl, double t, double h, const duffid_ctrl_input *in,
                     duffid_ctrl_output *out)
{
    const duffid_ctrl_config *p = &ctrl->cfg;
    int n = p->dofs, i, ok, changed, sw;
    double f_k = ctrl->f, g, f2, e, rp[3];
    duffid_ctrl before;
    if (!ctrl->initialized) return DUFFID_CTRL_ERR_STATE;
    if (fabs(h - p->sample_period) > DT_RTOL * p->sample_period) return DUFFID_CTRL_ERR_STEP;
    if (!isfinite(in->r) || !isfinite(in->r_dot) || !isfinite(in->r_ddot)) return DUFFID_CTRL_ERR_INPUT;
    for (i = 0; i < n; i++)
        if (!isfinite(in->x[i])) return DUFFID_CTRL_ERR_INPUT;
    before = *ctrl;
    ok = usable(ctrl, in);
    if (ctrl->phase == 0) {
        int size = p->differentiator_samples;
        ctrl->head = (ctrl->head + 1) % size;
        for (i = 0; i < n; i++) ctrl->buf[i][ctrl->head] = in->x[i];
        if (ctrl->count < size) ctrl->count++;
        if (!ok) {
            ctrl->have_ref = 0;
        } else if (!ctrl->have_ref) {
            memcpy(ctrl->p_ref, in->estimate, sizeof ctrl->p_ref);
            ctrl->settle_start = t;
            ctrl->have_ref = 1;
        } else {
            changed = 0;
            for (i = 0; i < ctrl->n_params; i++)
                if (fabs(in->estimate[i] - ctrl->p_ref[i]) > p->settle_tolerance * fabs(ctrl->p_ref[i])) changed = 1;
            if (changed) {
                memcpy(ctrl->p_ref, in->estimate, sizeof ctrl->p_ref);
                ctrl->settle_start = t;
            }
        }
        if (p->mode == 0)
            sw = ctrl->count >= size && ctrl->have_ref && t - ctrl->settle_start >= p->settle_time &&
                 t - ctrl->t0 >= p->min_excitation;
        else
            sw = ctrl->count >= size && t + h >= p->switch_time - SWITCH_RTOL * h;
        if (!sw) {
            ctrl->f = excitation(ctrl, t + h);
        } else {
            for (i = 0; i < ctrl->n_params; i++) ctrl->theta[i] = p->mode == 0 ? in->estimate[i] : p->nominal[i];
            for (i = 0; i < n; i++) {
                ctrl->xh[i] = in->x[i];
                ctrl->vh[i] = derivative(ctrl, i, h);
            }
            predict(ctrl, f_k, h);
            coupling(n, ctrl->theta, ctrl->xh, ctrl->vh, &g, &f2);
            ctrl->ref[0] = ctrl->xh[0];
            ctrl->ref[1] = ctrl->vh[0];
            ctrl->ref[2] = (f_k - g) / ctrl->theta[0];
            if (p->reference_model == 1) { /* x_d = r + z: z starts at the filter's start */
                predicted_reference(in, h, rp);
                for (i = 0; i < 3; i++) ctrl->z[i] = ctrl->ref[i] - rp[i];
            }
            ctrl->phase = 1;
            ctrl->switch_time = t + h;
            law(ctrl);
        }
    } else {
        if (p->mode == 0 && !p->freeze && ok)
            for (i = 0; i < ctrl->n_params; i++) ctrl->theta[i] = in->estimate[i];
        else if (p->mode == 0 && !p->freeze && p->fallback == 1)
            for (i = 0; i < ctrl->n_params; i++) ctrl->theta[i] = p->nominal[i];
        for (i = 0; i < n; i++) {
            e = in->x[i] - ctrl->xh[i];
            ctrl->xh[i] = ctrl->xh[i] + p->L[0] * e;
            ctrl->vh[i] = ctrl->vh[i] + p->L[1] * e;
        }
        predict(ctrl, f_k, h);
        if (p->reference_model == 0) {
            advance_reference(ctrl, ctrl->ref, in->r, h);
        } else {
            advance_reference(ctrl, ctrl->z, 0.0, h);
            predicted_reference(in, h, rp);
            for (i = 0; i < 3; i++) ctrl->ref[i] = rp[i] + ctrl->z[i];
        }
        law(ctrl);
    }
    ctrl->f_sample = 0.5 * (f_k + ctrl->f);
    if (bad_values(ctrl) != NULL) { /* diverged (overflow): refused, the controller unchanged */
        *ctrl = before;
        return DUFFID_CTRL_ERR_NUMERIC;
    }
    if (out != NULL) duffid_ctrl_outputs(ctrl, out);
    return DUFFID_CTRL_OK;
}

int duffid_ctrl_check_state(const duffid_ctrl *ctrl, char *msg, size_t msg_size)
{
    const duffid_ctrl_config *p = &ctrl->cfg;
    duffid_ctrl fresh;
    const char *bad = NULL;
    int size, j;
    if (duffid_ctrl_check(p, msg, msg_size) != DUFFID_CTRL_OK) return DUFFID_CTRL_ERR_STATE;
    if (!isfinite(ctrl->t0)) {
        message(msg, msg_size, "controller field %s = %.17g is not finite", "t0", ctrl->t0);
        return DUFFID_CTRL_ERR_STATE;
    }
    duffid_ctrl_init(&fresh, p, ctrl->t0, NULL, NULL, 0);
    size = p->differentiator_samples;
    if (ctrl->n_params != fresh.n_params) bad = "n_params";
    for (j = 0; bad == NULL && j < DUFFID_CTRL_MAX_SAMPLES; j++)
        if (!same_bits(ctrl->c[j], fresh.c[j])) bad = "c (differentiator weights)";
    if (bad == NULL && !(same_bits(ctrl->w3, fresh.w3) && same_bits(ctrl->w2, fresh.w2) &&
                         same_bits(ctrl->w1, fresh.w1)))
        bad = "w1, w2, w3 (reference model)";
    if (bad == NULL && ctrl->initialized != 1) bad = "initialized";
    if (bad == NULL && !(ctrl->head >= 0 && ctrl->head < size)) bad = "head";
    if (bad == NULL && !(ctrl->count >= 0 && ctrl->count <= size)) bad = "count";
    if (bad == NULL && ctrl->have_ref != 0 && ctrl->have_ref != 1) bad = "have_ref";
    if (bad == NULL && ctrl->phase != 0 && ctrl->phase != 1) bad = "phase";
    if (bad == NULL && ctrl->saturated != 0 && ctrl->saturated != 1) bad = "saturated";
    if (bad == NULL) bad = bad_values(ctrl);
    if (bad != NULL) {
        if (msg != NULL && msg_size > 0) snprintf(msg, msg_size, "controller field %s out of range", bad);
        return DUFFID_CTRL_ERR_STATE;
    }
    return DUFFID_CTRL_OK;
}
