/* FMI API fuzzing host: random call sequences against an FMU's FMI 2 or FMI 3 co-simulation API.
 *
 * Loads a co-simulation FMU's binary (dlopen) and, from a seeded PRNG, makes random calls of
 * every kind in whatever state the instance is in: lifecycle calls (setup, enter/exit
 * initialisation, terminate, reset), gets and sets of every type with valid and wrong value
 * references (unknown, of another type), NULL arrays, NaN/Inf values, parameters and outputs
 * set in states that forbid it, doSteps with bad steps (negative, zero, NaN, Inf, past the stop
 * time, at a wrong current time), the status functions, FMU state calls (NULL pointers, buffers
 * too small, garbage bytes), debug logging with unknown categories and Model Exchange functions
 * on a co-simulation instance. The oracle is the FMI state machine, tracked by the host:
 *
 *   illegal   a call the standard forbids in the current state or with these arguments: it
 *             must return Error (or Discard) and log a message of that status; it must not
 *             change the state (the glue refuses without side effects);
 *   legal     it must return OK or Warning, except a doStep, which may return Discard with a
 *             logged message (the step is then failed: only gets, status, terminate, reset, free);
 *   either    not judged (e.g. anything after an Error of a legal call, when the FMU is in
 *             its Error state).
 *
 * After the sequence the instance is reset and a valid run (setup, parameters, initialisation,
 * steps with deterministic inputs) must give, bit for bit, the outputs of the same run on a fresh
 * instance. Then `cycles` instantiate / initialise / step / terminate / free cycles measure the
 * resident memory (RSS) and the open file descriptors after a warm-up tenth and at the end.
 *
 *   fuzz_api <binary> <spec> [--fmi 2|3] [--calls N] [--seed S] [--cycles C] [--timeout SECONDS]
 *
 * Spec (written by tests/test_fmu_api_fuzz.py from modelDescription.xml):
 *   identifier <modelIdentifier>
 *   token <guid / instantiationToken>
 *   resources <FMI 2 URI> <FMI 3 path>
 *   dt <communication step>
 *   fmu_state 0|1                   canGetAndSetFMUstate
 *   var <vr> <R|I|B> <causality> <variability> <non_finite 0|1> <settable_start 0|1> <start> <name>
 *       causality: parameter calculatedParameter input output local independent; non_finite: may be
 *       set to NaN/Inf; settable_start: initial exact or approx (settable before initialisation)
 *
 * Output: violations (up to 40), then
 *   RESULT fmi= calls= illegal= refused= legal= legal_failed= violations= silent= coverage=
 *          valid_after=0|1 cycles= rss_kb_warm= rss_kb_end= fds_warm= fds_end=
 * (refused: illegal calls that returned Error/Discard; silent: refusals without a logged message;
 * coverage: "function x state" pairs visited out of the possible ones). Exit status 0 whatever the
 * counts (the test judges them), 2 on a setup error; a crash or a sanitizer report ends the process
 * (sanitizer exit code 86).
 *
 * Build: cc -std=gnu99 [-fsanitize=address,undefined ...] -I<fmpy>/c-code tests/c/fuzz_api.c -ldl -lm
 */
#define _GNU_SOURCE
#include <dirent.h>
#include <dlfcn.h>
#include <math.h>
#include <signal.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "fmi2Functions.h"
#include "fmi3FunctionTypes.h"

const char *__asan_default_options(void);
const char *__ubsan_default_options(void);
const char *__asan_default_options(void) { return "exitcode=86:detect_leaks=1"; }
const char *__ubsan_default_options(void) { return "exitcode=86:print_stacktrace=1:halt_on_error=1"; }

#define MAX_VARS 256
#define MAX_REPORTED 40
#define VALID_STEPS 20

/* ------------------------------------------------------------------ spec */

enum { C_PARAMETER, C_CALCULATED, C_INPUT, C_OUTPUT, C_LOCAL, C_INDEPENDENT };
enum { V_CONSTANT, V_FIXED, V_TUNABLE, V_DISCRETE, V_CONTINUOUS };

typedef struct {
    unsigned vr;
    char type; /* R I B */
    int causality, variability, non_finite, settable_start;
    double start;
    char name[96];
} Var;

typedef struct {
    char identifier[256], token[256], uri[4096], path[4096];
    double dt;
    int fmu_state;
    Var vars[MAX_VARS];
    int n_vars;
    unsigned max_vr;
} Spec;

static void die(const char *fmt, ...)
{
    va_list args;
    va_start(args, fmt);
    fprintf(stderr, "fuzz_api: ");
    vfprintf(stderr, fmt, args);
    fprintf(stderr, "\n");
    va_end(args);
    exit(2);
}

static int code_of(const char *word, const char *const *names, int n)
{
    int i;
    for (i = 0; i < n; i++)
        if (strcmp(word, names[i]) == 0) return i;
    die("unknown word %s in the spec", word);
    return -1;
}

static void read_spec(const char *file, Spec *s)
{
    static const char *const causalities[] = {"parameter", "calculatedParameter", "input", "output", "local",
                                              "independent"};
    static const char *const variabilities[] = {"constant", "fixed", "tunable", "discrete", "continuous"};
    char line[8192], key[64];
    FILE *f = fopen(file, "r");
    if (f == NULL) die("cannot open %s", file);
    memset(s, 0, sizeof *s);
    while (fgets(line, sizeof line, f)) {
        if (sscanf(line, "%63s", key) != 1) continue;
        if (strcmp(key, "identifier") == 0) sscanf(line, "%*s %255s", s->identifier);
        else if (strcmp(key, "token") == 0) sscanf(line, "%*s %255s", s->token);
        else if (strcmp(key, "resources") == 0) sscanf(line, "%*s %4095s %4095s", s->uri, s->path);
        else if (strcmp(key, "dt") == 0) sscanf(line, "%*s %lf", &s->dt);
        else if (strcmp(key, "fmu_state") == 0) sscanf(line, "%*s %d", &s->fmu_state);
        else if (strcmp(key, "var") == 0) {
            Var *v = &s->vars[s->n_vars];
            char type[8], caus[32], var[32], start[64];
            if (s->n_vars >= MAX_VARS) die("too many variables");
            if (sscanf(line, "%*s %u %7s %31s %31s %d %d %63s %95s", &v->vr, type, caus, var, &v->non_finite,
                       &v->settable_start, start, v->name) != 8)
                die("bad line: %s", line);
            v->type = type[0];
            v->causality = code_of(caus, causalities, 6);
            v->variability = code_of(var, variabilities, 5);
            v->start = strtod(start, NULL);
            if (v->vr > s->max_vr) s->max_vr = v->vr;
            s->n_vars++;
        }
    }
    fclose(f);
    if (!s->identifier[0] || !s->token[0] || !(s->dt > 0)) die("incomplete spec %s", file);
}

/* ------------------------------------------------------------------ PRNG (xorshift64*) */

static uint64_t rng_state;
static uint64_t rnd(void)
{
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    return rng_state * 2685821657736338717ULL;
}
static int rnd_int(int n) { return (int)(rnd() % (uint64_t)n); }
static double rnd_unit(void) { return (double)(rnd() >> 11) * (1.0 / 9007199254740992.0); }

/* ------------------------------------------------------------------ the FMU's functions */

typedef struct {
    void *lib;
    int fmi;
    /* FMI 2 */
    fmi2InstantiateTYPE *i2;
    fmi2FreeInstanceTYPE *free2;
    fmi2SetupExperimentTYPE *setup2;
    fmi2EnterInitializationModeTYPE *enter2;
    fmi2ExitInitializationModeTYPE *exit2;
    fmi2TerminateTYPE *term2;
    fmi2ResetTYPE *reset2;
    fmi2GetRealTYPE *get_real2;
    fmi2GetIntegerTYPE *get_int2;
    fmi2GetBooleanTYPE *get_bool2;
    fmi2GetStringTYPE *get_string2;
    fmi2SetRealTYPE *set_real2;
    fmi2SetIntegerTYPE *set_int2;
    fmi2SetBooleanTYPE *set_bool2;
    fmi2SetStringTYPE *set_string2;
    fmi2DoStepTYPE *step2;
    fmi2GetStatusTYPE *status2;
    fmi2GetRealStatusTYPE *real_status2;
    fmi2GetBooleanStatusTYPE *bool_status2;
    fmi2GetFMUstateTYPE *get_state2;
    fmi2SetFMUstateTYPE *set_state2;
    fmi2FreeFMUstateTYPE *free_state2;
    fmi2SerializedFMUstateSizeTYPE *state_size2;
    fmi2SerializeFMUstateTYPE *serialize2;
    fmi2DeSerializeFMUstateTYPE *deserialize2;
    fmi2SetDebugLoggingTYPE *debug2;
    fmi2CancelStepTYPE *cancel2;
    fmi2SetTimeTYPE *set_time2;
    fmi2SetRealInputDerivativesTYPE *input_der2;
    /* FMI 3 */
    fmi3InstantiateCoSimulationTYPE *i3;
    fmi3FreeInstanceTYPE *free3;
    fmi3EnterInitializationModeTYPE *enter3;
    fmi3ExitInitializationModeTYPE *exit3;
    fmi3TerminateTYPE *term3;
    fmi3ResetTYPE *reset3;
    fmi3GetFloat64TYPE *get_real3;
    fmi3GetInt32TYPE *get_int3;
    fmi3GetBooleanTYPE *get_bool3;
    fmi3GetStringTYPE *get_string3;
    fmi3SetFloat64TYPE *set_real3;
    fmi3SetInt32TYPE *set_int3;
    fmi3SetBooleanTYPE *set_bool3;
    fmi3SetStringTYPE *set_string3;
    fmi3DoStepTYPE *step3;
    fmi3EnterStepModeTYPE *step_mode3;
    fmi3GetFMUStateTYPE *get_state3;
    fmi3SetFMUStateTYPE *set_state3;
    fmi3FreeFMUStateTYPE *free_state3;
    fmi3SerializedFMUStateSizeTYPE *state_size3;
    fmi3SerializeFMUStateTYPE *serialize3;
    fmi3DeserializeFMUStateTYPE *deserialize3;
    fmi3SetDebugLoggingTYPE *debug3;
    fmi3SetTimeTYPE *set_time3;
    fmi3UpdateDiscreteStatesTYPE *update3;
} Api;

static void *sym(void *lib, const char *name)
{
    void *p = dlsym(lib, name);
    if (p == NULL) die("the binary does not export %s", name);
    return p;
}

#define LOAD(field, name) *(void **)(&api->field) = sym(api->lib, name)

static void load_api(Api *api, const char *binary, int fmi)
{
    memset(api, 0, sizeof *api);
    api->fmi = fmi;
    api->lib = dlopen(binary, RTLD_NOW | RTLD_LOCAL);
    if (api->lib == NULL) die("cannot load %s: %s", binary, dlerror());
    if (fmi == 2) {
        LOAD(i2, "fmi2Instantiate"); LOAD(free2, "fmi2FreeInstance"); LOAD(setup2, "fmi2SetupExperiment");
        LOAD(enter2, "fmi2EnterInitializationMode"); LOAD(exit2, "fmi2ExitInitializationMode");
        LOAD(term2, "fmi2Terminate"); LOAD(reset2, "fmi2Reset"); LOAD(get_real2, "fmi2GetReal");
        LOAD(get_int2, "fmi2GetInteger"); LOAD(get_bool2, "fmi2GetBoolean"); LOAD(get_string2, "fmi2GetString");
        LOAD(set_real2, "fmi2SetReal"); LOAD(set_int2, "fmi2SetInteger"); LOAD(set_bool2, "fmi2SetBoolean");
        LOAD(set_string2, "fmi2SetString"); LOAD(step2, "fmi2DoStep"); LOAD(status2, "fmi2GetStatus");
        LOAD(real_status2, "fmi2GetRealStatus"); LOAD(bool_status2, "fmi2GetBooleanStatus");
        LOAD(get_state2, "fmi2GetFMUstate"); LOAD(set_state2, "fmi2SetFMUstate"); LOAD(free_state2, "fmi2FreeFMUstate");
        LOAD(state_size2, "fmi2SerializedFMUstateSize"); LOAD(serialize2, "fmi2SerializeFMUstate");
        LOAD(deserialize2, "fmi2DeSerializeFMUstate"); LOAD(debug2, "fmi2SetDebugLogging");
        LOAD(cancel2, "fmi2CancelStep"); LOAD(set_time2, "fmi2SetTime");
        LOAD(input_der2, "fmi2SetRealInputDerivatives");
    } else {
        LOAD(i3, "fmi3InstantiateCoSimulation"); LOAD(free3, "fmi3FreeInstance");
        LOAD(enter3, "fmi3EnterInitializationMode"); LOAD(exit3, "fmi3ExitInitializationMode");
        LOAD(term3, "fmi3Terminate"); LOAD(reset3, "fmi3Reset"); LOAD(get_real3, "fmi3GetFloat64");
        LOAD(get_int3, "fmi3GetInt32"); LOAD(get_bool3, "fmi3GetBoolean"); LOAD(get_string3, "fmi3GetString");
        LOAD(set_real3, "fmi3SetFloat64"); LOAD(set_int3, "fmi3SetInt32"); LOAD(set_bool3, "fmi3SetBoolean");
        LOAD(set_string3, "fmi3SetString"); LOAD(step3, "fmi3DoStep"); LOAD(step_mode3, "fmi3EnterStepMode");
        LOAD(get_state3, "fmi3GetFMUState"); LOAD(set_state3, "fmi3SetFMUState"); LOAD(free_state3, "fmi3FreeFMUState");
        LOAD(state_size3, "fmi3SerializedFMUStateSize"); LOAD(serialize3, "fmi3SerializeFMUState");
        LOAD(deserialize3, "fmi3DeserializeFMUState"); LOAD(debug3, "fmi3SetDebugLogging");
        LOAD(set_time3, "fmi3SetTime"); LOAD(update3, "fmi3UpdateDiscreteStates");
    }
}

/* ------------------------------------------------------------------ logging */

static int force_valid; /* the next call with valid arguments (variant 0) */
#define VARIANT(n) (force_valid ? 0 : rnd_int(n))
static int logged_worst = -1; /* worst status logged since the last reset of this counter */
static int quiet = 1;

static void note(int status, const char *message)
{
    if (status > logged_worst) logged_worst = status;
    if (!quiet) fprintf(stderr, "  [%d] %s\n", status, message ? message : "");
}

static void logger2(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                    fmi2String message, ...)
{
    (void)env; (void)name; (void)category;
    note((int)status, message);
}

static void logger3(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env; (void)category;
    note((int)status, message);
}

static fmi2CallbackFunctions callbacks2 = {logger2, calloc, free, NULL, NULL};

/* ------------------------------------------------------------------ the host's view of the state */

enum { S_INSTANTIATED, S_INITIALIZATION, S_STEP, S_FAILED, S_TERMINATED, S_ERROR, N_STATES };
static const char *const STATE_NAMES[N_STATES] = {"Instantiated", "Initialization", "Step", "StepFailed",
                                                  "Terminated", "Error"};

typedef struct {
    const Spec *spec;
    Api *api;
    void *c;
    int state;
    double time, stop;
    int stop_defined;
    void *fmu_state; /* a state got from this instance (NULL: none) */
    int saved_state, saved_stop_defined; /* the host's view when it was got */
    double saved_time, saved_stop;
} Host;

static void *instantiate(Api *api, const Spec *s, const char *name, const char *token)
{
    if (api->fmi == 2)
        return api->i2(name, fmi2CoSimulation, token, s->uri, &callbacks2, fmi2False, fmi2False);
    return api->i3(name, token, s->path, fmi3False, fmi3False, fmi3False, fmi3False, NULL, 0, NULL, logger3, NULL);
}

static void free_instance(Host *h)
{
    if (h->c == NULL) return;
    if (h->fmu_state != NULL) {
        if (h->api->fmi == 2) h->api->free_state2(h->c, &h->fmu_state);
        else h->api->free_state3(h->c, &h->fmu_state);
        h->fmu_state = NULL;
    }
    if (h->api->fmi == 2) h->api->free2(h->c);
    else h->api->free3(h->c);
    h->c = NULL;
}

/* ------------------------------------------------------------------ counts and the oracle */

enum { LEGAL = 1, ILLEGAL = 0, EITHER = -1 };

/* the functions of the fuzzer (coverage: function x state) */
enum { F_SETUP, F_ENTER, F_EXIT, F_TERMINATE, F_RESET, F_GET, F_SET, F_STEP, F_STATUS, F_STATE, F_SERIAL,
       F_DEBUG, F_OTHER, N_FUNCS };
static const char *const FUNC_NAMES[N_FUNCS] = {"setup", "enterInit", "exitInit", "terminate", "reset", "get",
                                                "set", "doStep", "status", "FMUstate", "serialize", "debugLogging",
                                                "ME/unsupported"};

static long n_calls, n_illegal, n_refused, n_legal, n_legal_failed, n_violations, n_silent;
static int coverage[N_FUNCS][N_STATES];

static void violation(const Host *h, const char *what, int func, int status, const char *detail)
{
    n_violations++;
    if (n_violations <= MAX_REPORTED)
        printf("VIOLATION %s: %s in state %s returned %d (%s)\n", what, FUNC_NAMES[func], STATE_NAMES[h->state],
               status, detail);
}

/* Judges one call; returns its status. */
static int judge(Host *h, int func, int legal, int status, const char *detail)
{
    n_calls++;
    coverage[func][h->state] = 1;
    if (legal == ILLEGAL) {
        n_illegal++;
        if (status == fmi2Error || status == fmi2Discard) {
            n_refused++;
            if (logged_worst < fmi2Discard) n_silent++;
        } else {
            violation(h, "illegal call accepted", func, status, detail);
        }
    } else if (legal == LEGAL) {
        n_legal++;
        if (status > fmi2Warning) n_legal_failed++;
    }
    return status;
}

/* ------------------------------------------------------------------ values */

static const Var *pick_var(const Spec *s, char type, int want_causality)
{
    int i, n = 0, idx[MAX_VARS];
    for (i = 0; i < s->n_vars; i++)
        if ((type == 0 || s->vars[i].type == type) && (want_causality < 0 || s->vars[i].causality == want_causality))
            idx[n++] = i;
    return n ? &s->vars[idx[rnd_int(n)]] : NULL;
}

static int settable(const Host *h, const Var *v)
{
    if (v->causality == C_INPUT) return h->state <= S_STEP;
    if (v->causality == C_PARAMETER && (v->variability == V_FIXED || v->variability == V_TUNABLE))
        return h->state <= S_INITIALIZATION || (v->variability == V_TUNABLE && h->state == S_STEP);
    return v->settable_start && h->state <= S_INITIALIZATION;
}

static double valid_value(const Var *v)
{
    if (v->causality == C_PARAMETER) return v->start; /* parameters: their start (a valid value) */
    if (v->type == 'B') return (double)rnd_int(2);
    if (v->type == 'I') return v->start;
    if (v->non_finite && rnd_int(4) == 0) return NAN;
    return (isfinite(v->start) ? v->start : 0.0) + 0.01 * (rnd_unit() - 0.5);
}

/* ------------------------------------------------------------------ the calls */

static int do_get(Host *h)
{
    const Spec *s = h->spec;
    Api *a = h->api;
    int variant = VARIANT(8), legal_state = h->state >= S_INITIALIZATION, status, legal;
    char type = "RIB"[rnd_int(3)];
    const Var *v = pick_var(s, type, -1);
    unsigned vr[2];
    double r[2];
    int i2[2];
    fmi3Boolean b3[2];
    fmi2String str[2];
    size_t n = 1;
    const unsigned *vrp = vr;
    void *valp = type == 'R' ? (void *)r : type == 'B' && a->fmi == 3 ? (void *)b3 : (void *)i2;
    if (v == NULL) { type = 'R'; v = pick_var(s, 'R', -1); valp = r; }
    vr[0] = vr[1] = v->vr;
    legal = legal_state ? LEGAL : ILLEGAL;
    if (variant == 1) { vr[0] = s->max_vr + 1 + (unsigned)rnd_int(1000); legal = ILLEGAL; }
    else if (variant == 2) { vr[0] = 0xFFFFFFFFu; legal = ILLEGAL; }
    else if (variant == 3) { vrp = NULL; legal = ILLEGAL; }
    else if (variant == 4) { valp = NULL; legal = ILLEGAL; }
    else if (variant == 5) { n = 0; vrp = NULL; valp = NULL; } /* nothing to get: allowed */
    else if (variant == 6) { /* a variable of another type */
        const Var *w = pick_var(s, type == 'R' ? (rnd_int(2) ? 'I' : 'B') : 'R', -1);
        if (w != NULL) { vr[0] = w->vr; legal = ILLEGAL; }
    } else if (variant == 7 && a->fmi == 2) { /* a String get of a Real's reference */
        logged_worst = -1;
        status = a->get_string2(h->c, vr, 1, str);
        return judge(h, F_GET, ILLEGAL, status, "fmi2GetString of a non-String");
    }
    if (h->state == S_ERROR) legal = EITHER;
    logged_worst = -1;
    if (a->fmi == 2) {
        status = type == 'R' ? a->get_real2(h->c, vrp, n, (double *)valp)
                 : type == 'I' ? a->get_int2(h->c, vrp, n, (int *)valp) : a->get_bool2(h->c, vrp, n, (int *)valp);
    } else {
        size_t nv = n;
        if (variant == 0 && !force_valid && rnd_int(4) == 0 && n == 1) { nv = 2; legal = ILLEGAL; } /* nValues != n */
        status = type == 'R' ? a->get_real3(h->c, vrp, n, (double *)valp, nv)
                 : type == 'I' ? a->get_int3(h->c, vrp, n, (int *)valp, nv) : a->get_bool3(h->c, vrp, n, (fmi3Boolean *)valp, nv);
    }
    return judge(h, F_GET, legal, status, "get");
}

static int do_set(Host *h)
{
    const Spec *s = h->spec;
    Api *a = h->api;
    int variant = VARIANT(8), status, legal;
    const Var *v = pick_var(s, 0, -1);
    unsigned vr[1];
    double value;
    int iv;
    fmi3Boolean bv;
    size_t n = 1;
    const unsigned *vrp = vr;
    int null_values = 0;
    char type;
    if (rnd_int(3) > 0) { /* mostly inputs and parameters */
        const Var *w = pick_var(s, 0, rnd_int(2) ? C_INPUT : C_PARAMETER);
        if (w != NULL) v = w;
    }
    type = v->type;
    vr[0] = v->vr;
    value = valid_value(v);
    legal = settable(h, v) ? LEGAL : ILLEGAL;
    if (variant == 1) { vr[0] = s->max_vr + 1 + (unsigned)rnd_int(1000); legal = ILLEGAL; }
    else if (variant == 2) { vrp = NULL; legal = ILLEGAL; }
    else if (variant == 3) { null_values = 1; legal = ILLEGAL; }
    else if (variant == 4 && type == 'R') { /* NaN / Inf where not allowed */
        static const double bad[] = {NAN, INFINITY, -INFINITY};
        value = bad[rnd_int(3)];
        if (!v->non_finite) legal = ILLEGAL;
    } else if (variant == 5) { /* as another type */
        type = type == 'R' ? (rnd_int(2) ? 'I' : 'B') : 'R';
        legal = ILLEGAL;
    } else if (variant == 6) { n = 0; vrp = NULL; null_values = 1; legal = h->state <= S_STEP ? LEGAL : ILLEGAL; }
    if (h->state == S_ERROR) legal = EITHER;
    iv = isfinite(value) && fabs(value) < 2e9 ? (int)value : 0;
    bv = value != 0.0;
    logged_worst = -1;
    if (a->fmi == 2) {
        status = type == 'R' ? a->set_real2(h->c, vrp, n, null_values ? NULL : &value)
                 : type == 'I' ? a->set_int2(h->c, vrp, n, null_values ? NULL : &iv)
                 : a->set_bool2(h->c, vrp, n, null_values ? NULL : &iv);
    } else {
        size_t nv = n;
        if (variant == 7 && n == 1) { nv = 0; legal = ILLEGAL; }
        status = type == 'R' ? a->set_real3(h->c, vrp, n, null_values ? NULL : &value, nv)
                 : type == 'I' ? a->set_int3(h->c, vrp, n, null_values ? NULL : &iv, nv)
                 : a->set_bool3(h->c, vrp, n, null_values ? NULL : &bv, nv);
    }
    return judge(h, F_SET, legal, status, "set");
}

static void after_legal_failure(Host *h, int status)
{
    if (status == fmi2Error || status == fmi2Fatal) h->state = S_ERROR;
}

static int do_step(Host *h)
{
    Api *a = h->api;
    int variant = VARIANT(9), legal = h->state == S_STEP ? LEGAL : ILLEGAL, status;
    double t = h->time, dt = h->spec->dt;
    fmi3Boolean ev = 0, term = 0, early = 0;
    fmi3Float64 last = 0;
    int null_out = 0;
    switch (variant) {
    case 1: dt = -dt; legal = ILLEGAL; break;
    case 2: dt = 0.0; legal = ILLEGAL; break;
    case 3: dt = NAN; legal = ILLEGAL; break;
    case 4: dt = INFINITY; legal = ILLEGAL; break;
    case 5: t = h->time + 7.0 * h->spec->dt; legal = ILLEGAL; break; /* wrong current time */
    case 6: t = NAN; legal = ILLEGAL; break;
    case 7: if (h->stop_defined) { dt = (h->stop - t) + 5.0 * h->spec->dt; legal = ILLEGAL; } break; /* past stop */
    case 8: if (a->fmi == 3) { null_out = 1; legal = ILLEGAL; } break;
    default: break;
    }
    if (legal == LEGAL && h->stop_defined && t + dt > h->stop * (1 + 1e-12) + 1e-12) legal = ILLEGAL;
    if (h->state == S_ERROR) legal = EITHER;
    logged_worst = -1;
    if (a->fmi == 2) status = a->step2(h->c, t, dt, fmi2True);
    else status = a->step3(h->c, t, dt, fmi3True, null_out ? NULL : &ev, &term, &early, &last);
    judge(h, F_STEP, legal, status, "doStep");
    if (legal == LEGAL) {
        if (status <= fmi2Warning && !term) h->time = t + dt;
        else if (status == fmi2Discard || term) {
            h->state = S_FAILED;
            if (logged_worst < fmi2Discard && !term) n_silent++;
        } else after_legal_failure(h, status);
    }
    return status;
}

static int do_lifecycle(Host *h, int func)
{
    Api *a = h->api;
    int legal, status;
    if (func == F_SETUP) {
        int variant = VARIANT(6);
        double tol = 1e-6, start = 0.0, stop = 10.0 * h->spec->dt;
        int tol_defined = rnd_int(2), stop_defined = rnd_int(2);
        legal = h->state == S_INSTANTIATED ? LEGAL : ILLEGAL;
        if (variant == 1) { tol_defined = 1; tol = NAN; legal = ILLEGAL; }
        else if (variant == 2) { tol_defined = 1; tol = -1e-6; legal = ILLEGAL; }
        else if (variant == 3) { stop_defined = 1; stop = start - 1.0; legal = ILLEGAL; }
        else if (variant == 4) { start = NAN; legal = ILLEGAL; }
        if (a->fmi == 3) { /* FMI 3: setup is part of enterInitializationMode */
            logged_worst = -1;
            status = a->enter3(h->c, tol_defined, tol, start, stop_defined, stop);
            judge(h, F_ENTER, legal, status, "fmi3EnterInitializationMode");
        } else {
            logged_worst = -1;
            status = a->setup2(h->c, tol_defined, tol, start, stop_defined, stop);
            judge(h, F_SETUP, legal, status, "fmi2SetupExperiment");
        }
        if (legal == LEGAL) {
            if (status <= fmi2Warning) {
                h->time = start;
                h->stop = stop;
                h->stop_defined = stop_defined;
                if (a->fmi == 3) h->state = S_INITIALIZATION;
            } else after_legal_failure(h, status);
        }
        return status;
    }
    logged_worst = -1;
    switch (func) {
    case F_ENTER:
        legal = h->state == S_INSTANTIATED ? LEGAL : ILLEGAL;
        if (a->fmi == 3) return do_lifecycle(h, F_SETUP);
        status = a->enter2(h->c);
        break;
    case F_EXIT:
        legal = h->state == S_INITIALIZATION ? LEGAL : ILLEGAL;
        status = a->fmi == 2 ? a->exit2(h->c) : a->exit3(h->c);
        break;
    case F_TERMINATE:
        legal = h->state == S_STEP || h->state == S_FAILED ? LEGAL : ILLEGAL;
        status = a->fmi == 2 ? a->term2(h->c) : a->term3(h->c);
        break;
    default: /* reset */
        legal = LEGAL;
        if (h->fmu_state != NULL) {
            if (a->fmi == 2) a->free_state2(h->c, &h->fmu_state);
            else a->free_state3(h->c, &h->fmu_state);
            h->fmu_state = NULL;
        }
        status = a->fmi == 2 ? a->reset2(h->c) : a->reset3(h->c);
        break;
    }
    if (h->state == S_ERROR && func != F_RESET) legal = EITHER;
    judge(h, func, legal, status, FUNC_NAMES[func]);
    if (legal == LEGAL) {
        if (status > fmi2Warning) {
            after_legal_failure(h, status);
        } else {
            static const int next[] = {0, S_INITIALIZATION, S_STEP, S_TERMINATED, S_INSTANTIATED};
            h->state = next[func];
            if (func == F_RESET) { h->time = 0.0; h->stop_defined = 0; }
        }
    }
    return status;
}

static int do_status(Host *h)
{
    Api *a = h->api;
    int legal = (h->state == S_STEP || h->state == S_FAILED || h->state == S_TERMINATED) ? LEGAL : ILLEGAL, status;
    int variant = rnd_int(5);
    fmi2Status st;
    fmi2Real r;
    fmi2Boolean b;
    if (a->fmi == 3) { /* no status functions: fmi3EnterStepMode needs Event Mode (never, without event mode) */
        logged_worst = -1;
        status = a->step_mode3(h->c);
        return judge(h, F_STATUS, ILLEGAL, status, "fmi3EnterStepMode");
    }
    logged_worst = -1;
    if (variant == 0) status = a->status2(h->c, fmi2DoStepStatus, &st);
    else if (variant == 1) status = a->real_status2(h->c, fmi2LastSuccessfulTime, &r);
    else if (variant == 2) status = a->bool_status2(h->c, fmi2Terminated, &b);
    else if (variant == 3) { status = a->real_status2(h->c, fmi2LastSuccessfulTime, NULL); legal = ILLEGAL; }
    else { status = a->bool_status2(h->c, fmi2PendingStatus, &b); legal = ILLEGAL; }
    if (h->state == S_ERROR) legal = EITHER;
    return judge(h, F_STATUS, legal, status, "status");
}

static int do_fmu_state(Host *h)
{
    Api *a = h->api;
    int variant = rnd_int(4), status, legal = h->spec->fmu_state ? LEGAL : ILLEGAL;
    logged_worst = -1;
    if (variant == 0) { /* get (into the host's state) */
        status = a->fmi == 2 ? a->get_state2(h->c, &h->fmu_state) : a->get_state3(h->c, &h->fmu_state);
        if (status <= fmi2Warning && h->fmu_state != NULL) {
            h->saved_state = h->state;
            h->saved_time = h->time;
            h->saved_stop = h->stop;
            h->saved_stop_defined = h->stop_defined;
        }
    } else if (variant == 1) { /* NULL pointer to the state */
        status = a->fmi == 2 ? a->get_state2(h->c, NULL) : a->get_state3(h->c, NULL);
        legal = ILLEGAL;
    } else if (variant == 2) { /* set: NULL, or the state got before */
        void *state = h->fmu_state;
        if (state == NULL) legal = ILLEGAL;
        status = a->fmi == 2 ? a->set_state2(h->c, state) : a->set_state3(h->c, state);
        if (h->state == S_ERROR) legal = EITHER;
        judge(h, F_STATE, legal, status, "setFMUstate");
        if (legal != ILLEGAL && status <= fmi2Warning) { /* back to the state's view */
            h->state = h->saved_state;
            h->time = h->saved_time;
            h->stop = h->saved_stop;
            h->stop_defined = h->saved_stop_defined;
        }
        return status;
    } else { /* free a NULL state: allowed */
        void *none = NULL;
        status = a->fmi == 2 ? a->free_state2(h->c, &none) : a->free_state3(h->c, &none);
        legal = LEGAL;
    }
    if (h->state == S_ERROR) legal = EITHER;
    return judge(h, F_STATE, legal, status, "FMU state");
}

static int do_serialize(Host *h)
{
    Api *a = h->api;
    int variant = rnd_int(4), status, legal = ILLEGAL;
    size_t size = 0;
    char bytes[64];
    void *out = NULL;
    logged_worst = -1;
    if (variant == 0) { /* size into NULL */
        status = a->fmi == 2 ? a->state_size2(h->c, h->fmu_state, NULL) : a->state_size3(h->c, h->fmu_state, NULL);
    } else if (variant == 1 && h->fmu_state != NULL) { /* a buffer too small */
        status = a->fmi == 2 ? a->serialize2(h->c, h->fmu_state, bytes, 4)
                             : a->serialize3(h->c, h->fmu_state, (fmi3Byte *)bytes, 4);
    } else if (variant == 2) { /* garbage bytes */
        size_t i;
        for (i = 0; i < sizeof bytes; i++) bytes[i] = (char)rnd();
        status = a->fmi == 2 ? a->deserialize2(h->c, bytes, sizeof bytes, &out)
                             : a->deserialize3(h->c, (fmi3Byte *)bytes, sizeof bytes, &out);
        if (out != NULL) { /* accepted garbage: a violation, and a state to free */
            if (a->fmi == 2) a->free_state2(h->c, &out);
            else a->free_state3(h->c, &out);
        }
    } else if (h->fmu_state != NULL && h->spec->fmu_state) { /* the genuine round trip */
        legal = LEGAL;
        status = a->fmi == 2 ? a->state_size2(h->c, h->fmu_state, &size) : a->state_size3(h->c, h->fmu_state, &size);
        if (status <= fmi2Warning) {
            char *buffer = (char *)malloc(size);
            status = a->fmi == 2 ? a->serialize2(h->c, h->fmu_state, buffer, size)
                                 : a->serialize3(h->c, h->fmu_state, (fmi3Byte *)buffer, size);
            if (status <= fmi2Warning) {
                status = a->fmi == 2 ? a->deserialize2(h->c, buffer, size, &out)
                                     : a->deserialize3(h->c, (fmi3Byte *)buffer, size, &out);
                if (out != NULL) {
                    if (a->fmi == 2) a->free_state2(h->c, &out);
                    else a->free_state3(h->c, &out);
                }
            }
            free(buffer);
        }
    } else {
        status = a->fmi == 2 ? a->state_size2(h->c, NULL, &size) : a->state_size3(h->c, NULL, &size);
    }
    if (h->state == S_ERROR) legal = EITHER;
    return judge(h, F_SERIAL, legal, status, "serialize");
}

static int do_debug(Host *h)
{
    Api *a = h->api;
    int variant = rnd_int(3), status, legal = LEGAL;
    const char *known[] = {"logStatusError"}, *unknown[] = {"noSuchCategory"};
    logged_worst = -1;
    if (variant == 0) {
        status = a->fmi == 2 ? a->debug2(h->c, fmi2False, 1, known) : a->debug3(h->c, fmi3False, 1, known);
    } else if (variant == 1) {
        status = a->fmi == 2 ? a->debug2(h->c, fmi2False, 1, unknown) : a->debug3(h->c, fmi3False, 1, unknown);
        legal = ILLEGAL;
    } else {
        status = a->fmi == 2 ? a->debug2(h->c, fmi2False, 2, NULL) : a->debug3(h->c, fmi3False, 2, NULL);
        legal = ILLEGAL;
    }
    return judge(h, F_DEBUG, legal, status, "setDebugLogging");
}

static int do_other(Host *h)
{
    Api *a = h->api;
    int status;
    logged_worst = -1;
    if (a->fmi == 2) {
        int variant = rnd_int(3);
        unsigned vr = 0;
        int order = 1;
        double value = 0;
        if (variant == 0) status = a->set_time2(h->c, 1.0);          /* Model Exchange */
        else if (variant == 1) status = a->cancel2(h->c);           /* synchronous steps */
        else status = a->input_der2(h->c, &vr, 1, &order, &value);  /* canInterpolateInputs=false */
    } else {
        fmi3Boolean x;
        fmi3Float64 t;
        if (rnd_int(2)) status = a->set_time3(h->c, 1.0);
        else status = a->update3(h->c, &x, &x, &x, &x, &x, &t); /* Event Mode only */
    }
    return judge(h, F_OTHER, ILLEGAL, status, "ME/unsupported");
}

/* One random call; a quarter of them the valid next call of the lifecycle, so that every state
 * is visited. */
static void random_call(Host *h)
{
    int f;
    force_valid = rnd_int(4) == 0;
    if (force_valid) {
        switch (h->state) {
        case S_INSTANTIATED: f = rnd_int(3) == 0 ? F_SET : (h->api->fmi == 2 && rnd_int(2) ? F_SETUP : F_ENTER); break;
        case S_INITIALIZATION: f = rnd_int(3) == 0 ? F_SET : F_EXIT; break;
        case S_STEP: f = rnd_int(12) == 0 ? F_TERMINATE : rnd_int(3) == 0 ? F_SET : F_STEP; break;
        case S_FAILED: f = F_TERMINATE; break;
        default: f = F_RESET; break;
        }
    } else {
        f = rnd_int(N_FUNCS);
        if (f == F_RESET && rnd_int(4)) f = F_GET; /* resets are rarer: deeper sequences */
    }
    switch (f) {
    case F_GET: do_get(h); break;
    case F_SET: do_set(h); break;
    case F_STEP: do_step(h); break;
    case F_STATUS: do_status(h); break;
    case F_STATE: do_fmu_state(h); break;
    case F_SERIAL: do_serialize(h); break;
    case F_DEBUG: do_debug(h); break;
    case F_OTHER: do_other(h); break;
    default: do_lifecycle(h, f); break;
    }
    force_valid = 0;
}

/* ------------------------------------------------------------------ a valid run */

static int set_one(Api *a, void *c, const Var *v, double value)
{
    unsigned vr = v->vr;
    int iv = (int)value;
    fmi3Boolean bv = value != 0.0;
    if (a->fmi == 2)
        return v->type == 'R' ? a->set_real2(c, &vr, 1, &value)
               : v->type == 'I' ? a->set_int2(c, &vr, 1, &iv) : a->set_bool2(c, &vr, 1, &iv);
    return v->type == 'R' ? a->set_real3(c, &vr, 1, &value, 1)
           : v->type == 'I' ? a->set_int3(c, &vr, 1, &iv, 1) : a->set_bool3(c, &vr, 1, &bv, 1);
}

static int get_one(Api *a, void *c, const Var *v, double *value)
{
    unsigned vr = v->vr;
    int iv = 0, status;
    fmi3Boolean bv = 0;
    if (v->type == 'R')
        return a->fmi == 2 ? a->get_real2(c, &vr, 1, value) : a->get_real3(c, &vr, 1, value, 1);
    if (a->fmi == 2) status = v->type == 'I' ? a->get_int2(c, &vr, 1, &iv) : a->get_bool2(c, &vr, 1, &iv);
    else if (v->type == 'I') status = a->get_int3(c, &vr, 1, &iv, 1);
    else { status = a->get_bool3(c, &vr, 1, &bv, 1); iv = bv; }
    *value = iv;
    return status;
}

/* Setup, parameters, initialisation, VALID_STEPS steps with deterministic inputs; the outputs
 * after each step into out (n_steps x n_vars); nonzero when a call did not return OK. */
static int valid_run(Api *a, const Spec *s, void *c, double *out, int n_steps)
{
    int k, i, bad = 0;
    double t = 0.0;
    if (a->fmi == 2) bad |= a->setup2(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) > fmi2Warning;
    for (i = 0; i < s->n_vars; i++)
        if (s->vars[i].causality == C_PARAMETER && s->vars[i].variability != V_CONSTANT)
            bad |= set_one(a, c, &s->vars[i], s->vars[i].start) > fmi2Warning;
    bad |= (a->fmi == 2 ? a->enter2(c) : a->enter3(c, fmi3False, 0.0, 0.0, fmi3False, 0.0)) > fmi2Warning;
    bad |= (a->fmi == 2 ? a->exit2(c) : a->exit3(c)) > fmi2Warning;
    for (k = 0; k < n_steps && !bad; k++) {
        fmi3Boolean ev, term, early;
        fmi3Float64 last;
        for (i = 0; i < s->n_vars; i++) {
            const Var *v = &s->vars[i];
            if (v->causality != C_INPUT) continue;
            bad |= set_one(a, c, v, v->type == 'B' ? (double)((k / 5) % 2) : v->type == 'I' ? v->start
                                    : (isfinite(v->start) ? v->start : 0.0) + 0.01 * sin(0.7 * k + i)) > fmi2Warning;
        }
        bad |= (a->fmi == 2 ? a->step2(c, t, s->dt, fmi2True)
                            : a->step3(c, t, s->dt, fmi3True, &ev, &term, &early, &last)) > fmi2Warning;
        t = (k + 1) * s->dt;
        for (i = 0; i < s->n_vars; i++)
            bad |= get_one(a, c, &s->vars[i], &out[k * s->n_vars + i]) > fmi2Warning;
    }
    return bad;
}

static int same_outputs(const double *a, const double *b, size_t n)
{
    size_t i;
    for (i = 0; i < n; i++)
        if (!(a[i] == b[i] || (isnan(a[i]) && isnan(b[i])))) return 0;
    return 1;
}

/* ------------------------------------------------------------------ memory and descriptors */

static long rss_kb(void)
{
    long pages = 0, resident = 0;
    FILE *f = fopen("/proc/self/statm", "r");
    if (f == NULL) return -1;
    if (fscanf(f, "%ld %ld", &pages, &resident) != 2) resident = -1;
    fclose(f);
    return resident < 0 ? -1 : resident * (sysconf(_SC_PAGESIZE) / 1024);
}

static int open_fds(void)
{
    int n = 0;
    DIR *d = opendir("/proc/self/fd");
    struct dirent *e;
    if (d == NULL) return -1;
    while ((e = readdir(d)) != NULL)
        if (e->d_name[0] != '.') n++;
    closedir(d);
    return n - 1; /* the directory's own descriptor */
}

/* ------------------------------------------------------------------ main */

int main(int argc, char **argv)
{
    Spec spec;
    Api api;
    Host host;
    int fmi = 2, cycles = 2000, timeout = 600, i, states_possible = 0, visited = 0, valid_after;
    long calls = 20000, k, rss_warm = 0, rss_end = 0;
    int fds_warm = 0, fds_end = 0;
    uint64_t seed = 17;
    double *reference, *again;
    size_t n_out;
    if (argc < 3) die("usage: fuzz_api <binary> <spec> [--fmi 2|3] [--calls N] [--seed S] [--cycles C] [--timeout T]");
    for (i = 3; i + 1 < argc; i += 2) {
        if (strcmp(argv[i], "--fmi") == 0) fmi = atoi(argv[i + 1]);
        else if (strcmp(argv[i], "--calls") == 0) calls = atol(argv[i + 1]);
        else if (strcmp(argv[i], "--seed") == 0) seed = strtoull(argv[i + 1], NULL, 10);
        else if (strcmp(argv[i], "--cycles") == 0) cycles = atoi(argv[i + 1]);
        else if (strcmp(argv[i], "--timeout") == 0) timeout = atoi(argv[i + 1]);
        else die("unknown option %s", argv[i]);
    }
    if (fmi != 2 && fmi != 3) die("--fmi must be 2 or 3");
    alarm((unsigned)timeout); /* a hang ends the process (SIGALRM) */
    read_spec(argv[2], &spec);
    load_api(&api, argv[1], fmi);
    rng_state = seed * 0x9E3779B97F4A7C15ULL + 1;
    n_out = (size_t)VALID_STEPS * (size_t)spec.n_vars;
    reference = (double *)calloc(n_out, sizeof(double));
    again = (double *)calloc(n_out, sizeof(double));

    /* the reference valid run, on a fresh instance */
    memset(&host, 0, sizeof host);
    host.spec = &spec;
    host.api = &api;
    host.c = instantiate(&api, &spec, "reference", spec.token);
    if (host.c == NULL) die("the FMU does not instantiate");
    if (valid_run(&api, &spec, host.c, reference, VALID_STEPS) != 0) die("the valid run fails on a fresh instance");
    free_instance(&host);

    /* instantiation with wrong arguments: refused (NULL), logged */
    logged_worst = -1;
    host.c = instantiate(&api, &spec, "bad", "{not-the-token}");
    n_calls++; n_illegal++;
    if (host.c != NULL) { printf("VIOLATION instantiation with a wrong token accepted\n"); n_violations++; free_instance(&host); }
    else { n_refused++; if (logged_worst < fmi2Discard) n_silent++; }
    logged_worst = -1;
    host.c = instantiate(&api, &spec, "", spec.token);
    n_calls++; n_illegal++;
    if (host.c != NULL) { printf("VIOLATION instantiation with an empty name accepted\n"); n_violations++; free_instance(&host); }
    else { n_refused++; if (logged_worst < fmi2Discard) n_silent++; }
    logged_worst = -1;
    host.c = instantiate(&api, &spec, "bad", NULL);
    n_calls++; n_illegal++;
    if (host.c != NULL) { printf("VIOLATION instantiation with a NULL token accepted\n"); n_violations++; free_instance(&host); }
    else { n_refused++; if (logged_worst < fmi2Discard) n_silent++; }

    /* the random sequence, then a reset and the valid run on the same instance */
    host.c = instantiate(&api, &spec, "fuzzed", spec.token);
    if (host.c == NULL) die("the FMU does not instantiate");
    host.state = S_INSTANTIATED;
    for (k = 0; k < calls; k++) random_call(&host);
    if (host.fmu_state != NULL) {
        if (fmi == 2) api.free_state2(host.c, &host.fmu_state);
        else api.free_state3(host.c, &host.fmu_state);
        host.fmu_state = NULL;
    }
    valid_after = (fmi == 2 ? api.reset2(host.c) : api.reset3(host.c)) <= fmi2Warning &&
                  valid_run(&api, &spec, host.c, again, VALID_STEPS) == 0 && same_outputs(reference, again, n_out);
    free_instance(&host);

    /* instantiate / run / free cycles: memory and descriptors */
    for (i = 0; i < cycles; i++) {
        void *c = instantiate(&api, &spec, "cycle", spec.token);
        if (c == NULL) die("cycle %d: the FMU does not instantiate", i);
        if (valid_run(&api, &spec, c, again, 3) != 0) die("cycle %d: the valid run fails", i);
        if (fmi == 2) { api.term2(c); api.free2(c); } else { api.term3(c); api.free3(c); }
        if (i + 1 == (cycles + 9) / 10) { rss_warm = rss_kb(); fds_warm = open_fds(); }
    }
    rss_end = rss_kb();
    fds_end = open_fds();

    for (i = 0; i < N_FUNCS; i++) {
        int st;
        for (st = 0; st < N_STATES; st++) {
            if (st == S_ERROR || (st == S_FAILED && !coverage[F_STEP][S_FAILED] && !coverage[F_TERMINATE][S_FAILED]))
                continue;
            if (fmi == 3 && i == F_SETUP) continue;
            states_possible++;
            visited += coverage[i][st];
        }
    }
    printf("RESULT fmi=%d calls=%ld illegal=%ld refused=%ld legal=%ld legal_failed=%ld violations=%ld silent=%ld "
           "coverage=%d/%d valid_after=%d cycles=%d rss_kb_warm=%ld rss_kb_end=%ld fds_warm=%d fds_end=%d\n",
           fmi, n_calls, n_illegal, n_refused, n_legal, n_legal_failed, n_violations, n_silent, visited,
           states_possible, valid_after, cycles, rss_warm, rss_end, fds_warm, fds_end);
    free(reference);
    free(again);
    dlclose(api.lib);
    return 0;
}
