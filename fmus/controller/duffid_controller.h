/* duffid adaptive controller: portable C99 core (see README.md).
 *
 * Excitation until the online estimates are identified and settled, then a bumpless
 * switch to certainty-equivalence feedback linearisation of the Duffing oscillator
 * (1 DOF) or of the two-mass chain (2 DOF, force on m1, tracks x1), with a
 * predictor-corrector observer and a triple-pole reference model. The Python reference
 * duffid.control.adaptive.AdaptiveController performs the same floating-point operations in the
 * same order.
 *
 * Memory: a duffid_ctrl is a plain struct without pointers, owned by the caller (copy it
 * to save the controller's state); no allocation, no global or static mutable state.
 */
#ifndef DUFFID_CONTROLLER_H
#define DUFFID_CONTROLLER_H

#include <stddef.h>

#include "duffid_ctrl_params.h"

#ifdef __cplusplus
extern "C" {
#endif

#define DUFFID_CTRL_MAX_SAMPLES 64 /* largest differentiator_samples */
#define DUFFID_CTRL_MAX_PARAMS 8

/* Return codes. */
enum {
    DUFFID_CTRL_OK = 0,
    DUFFID_CTRL_ERR_CONFIG = 1, /* invalid configuration (message says which) */
    DUFFID_CTRL_ERR_STEP = 2,   /* step size differs from the sample period */
    DUFFID_CTRL_ERR_INPUT = 3,  /* reference, its derivatives or a position not finite */
    DUFFID_CTRL_ERR_STATE = 4,  /* step before init; a controller state that fails its checks */
    DUFFID_CTRL_ERR_NUMERIC = 5 /* the step would leave a value not finite (the observer or the
                                   reference model overflowed): refused */
};

/* Parameter order (estimates, nominal values, parameters used):
 * 1 DOF: m b k kp; 2 DOF: m1 b1 k1 kp1 b2 k2 kp2 m2 (the estimator's output order). */
typedef struct duffid_ctrl_config {
    int dofs;                    /* 1 or 2 */
    int mode;                    /* 0 adaptive, 1 fixed (baseline on nominal, at switch_time) */
    double sample_period;        /* s */
    int excitation;              /* 0 step, 1 linear chirp */
    double excitation_amplitude; /* N, |.| <= force_limit */
    double chirp_f0, chirp_f1;   /* Hz */
    double chirp_duration;       /* s (then f1) */
    double min_excitation;       /* s */
    double settle_time;          /* s */
    double settle_tolerance;     /* relative */
    double K[2], L[2];           /* feedback and observer gains */
    double reference_bandwidth;  /* rad/s */
    int reference_model;         /* 0 filter (triple pole driven by r), 1 derivatives (r + transient) */
    double force_limit;          /* N, > 0 */
    int differentiator_samples;  /* 3 .. DUFFID_CTRL_MAX_SAMPLES */
    int freeze;                  /* 1: keep the estimates of the switch */
    int fallback;                /* freeze 0, estimates withdrawn: 0 hold the law's parameters, 1 nominal */
    double nominal[DUFFID_CTRL_MAX_PARAMS];
    double switch_time;          /* s (mode 1; FMU parameter fixed_switch_time) */
} duffid_ctrl_config;

typedef struct duffid_ctrl_input {
    double r;                                /* reference position of x (2 DOF: x1) at t_k */
    double r_dot, r_ddot;                    /* its derivatives at t_k (reference_model 1) */
    double x[2];                             /* measured positions */
    double estimate[DUFFID_CTRL_MAX_PARAMS]; /* NaN allowed (not yet estimated) */
    int identified;
} duffid_ctrl_input;

typedef struct duffid_ctrl_output {
    double f;          /* force over [t_{k+1}, t_{k+2}) (after init: over [t_0, t_1)) */
    double f_sample;   /* the force as a sample at t_{k+1} for an identifier: the mean of the
                          forces over [t_k, t_{k+1}) and [t_{k+1}, t_{k+2}), which stands for the
                          zero-order-hold staircase to O(h^2) (after init: f) */
    int phase;         /* 0 excitation, 1 control */
    double x_ref;      /* desired position x_d at t_{k+1} (NaN before the switch) */
    double v_hat[2];   /* observer velocities at t_{k+1} (NaN before the switch) */
    int saturated;     /* the last command was limited */
    double switch_time; /* first time of the controlled force (NaN before the switch) */
    double used[DUFFID_CTRL_MAX_PARAMS]; /* parameters of the law (NaN before the switch) */
} duffid_ctrl_output;

typedef struct duffid_ctrl {
    duffid_ctrl_config cfg;
    int n_params;
    double c[DUFFID_CTRL_MAX_SAMPLES]; /* differentiator weights (per sample) */
    double w3, w2, w1;                 /* reference model: wr^3, 3 wr^2, 3 wr */
    double t0;
    double buf[2][DUFFID_CTRL_MAX_SAMPLES];
    int head, count;
    int have_ref;
    double p_ref[DUFFID_CTRL_MAX_PARAMS];
    double settle_start;
    int phase;
    double theta[DUFFID_CTRL_MAX_PARAMS];
    double xh[2], vh[2];
    double ref[3];                     /* x_d, x_d', x_d'' at t_{k+1} */
    double z[3];                       /* reference_model 1: transient, x_d = r + z */
    double switch_time;
    int saturated;
    double f;
    double f_sample;
    int initialized;
} duffid_ctrl;

/* Checks a configuration; DUFFID_CTRL_OK or DUFFID_CTRL_ERR_CONFIG with a message. */
int duffid_ctrl_check(const duffid_ctrl_config *cfg, char *msg, size_t msg_size);

/* Starts the controller at time t0 and gives the outputs at initialisation. */
int duffid_ctrl_init(duffid_ctrl *ctrl, const duffid_ctrl_config *cfg, double t0, duffid_ctrl_output *out,
                     char *msg, size_t msg_size);

/* Consumes the inputs at t (= t_k) with step h; the outputs are those at t + h. On an
 * error the controller is unchanged; a step that would leave a value the controller relies on
 * not finite (overflow, see duffid_ctrl_check_state) is refused with DUFFID_CTRL_ERR_NUMERIC. */
int duffid_ctrl_step(duffid_ctrl *ctrl, double t, double h, const duffid_ctrl_input *in,
                     duffid_ctrl_output *out);

/* The current outputs. */
void duffid_ctrl_outputs(const duffid_ctrl *ctrl, duffid_ctrl_output *out);

/* Checks a byte copy of a controller (an FMU state's) before it is used: a valid
 * configuration, the fields duffid_ctrl_init derives from it, buffer position and count within
 * the differentiator's samples, flags 0/1, and the values of each phase (finite where the
 * controller computes with them, NaN where it has not yet, forces within force_limit).
 * DUFFID_CTRL_OK, else DUFFID_CTRL_ERR_STATE with a message naming the field. */
int duffid_ctrl_check_state(const duffid_ctrl *ctrl, char *msg, size_t msg_size);

#ifdef __cplusplus
}
#endif

#endif
