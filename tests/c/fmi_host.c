/* fmi_host: a small FMI 2.0 / FMI 3.0 co-simulation host in portable C (tests of duffid's FMUs).
 *
 * It loads an FMU's binary itself (dlopen on POSIX, LoadLibrary on Windows; no other library),
 * sets start values, initialises, steps on the grid t_k = START + k * STEP (the step passed to
 * doStep is t_{k+1} - t_k, computed like fmpy does) and prints the outputs as CSV.
 *
 *   fmi_host [options] FMU_DIR VERSION BINARY TOKEN STEP STEPS
 *
 *   FMU_DIR   the unzipped FMU (its resources folder is passed to the FMU)
 *   VERSION   2 or 3
 *   BINARY    the shared library, e.g. FMU_DIR/binaries/linux64/X.so
 *   TOKEN     the GUID (FMI 2) or instantiationToken (FMI 3) of modelDescription.xml
 *   STEP      communication step size (s); STEPS: number of doStep calls (0: initialise only)
 *
 * A variable is named by its type letter and value reference: r13 (Real / Float64),
 * i21 (Integer / Int32), b9 (Boolean).
 *
 *   -p VAR=VALUE  set before initialisation (parameters; inputs that stay constant); repeatable
 *   -i VAR        an input read from the CSV of -c, one column per -i in that order; repeatable
 *   -o VAR        an output to print; repeatable
 *   -c FILE       input CSV: row k holds the inputs at t_k (set in initialisation mode for row 0,
 *                 then before each doStep); comma separated, no time column; a first line that
 *                 does not start with a number is a header; at least STEPS rows (STEPS = 0: one)
 *   -s START      start time (default 0); the stop time passed to the FMU is t_STEPS
 *   -r TOL        relative tolerance passed to the FMU (default: none defined)
 *   -l            loggingOn (the FMU's messages go to stderr either way)
 *
 * Output (stdout): a header "time,<VAR>,...", then one row after initialisation (t_0) and one
 * after each doStep (%.17g; Integer and Boolean as integers). Every FMI call's status is
 * checked: Warning is reported on stderr and the run continues; anything else stops the run
 * with a message naming the call and exit status 1. Usage errors exit with status 2. An FMU
 * asking to terminate ends the run early (a line on stderr, exit status 0).
 *
 * Build (the FMI headers are those fmpy ships in its c-code folder; tests/c_hosts.py does this):
 *   gcc -std=c99 -O2 -Wall -Wextra -Werror -pedantic -I<fmpy>/c-code fmi_host.c -o fmi_host -ldl
 *   x86_64-w64-mingw32-gcc <same flags> -static fmi_host.c -o fmi_host.exe     (run: wine64 fmi_host.exe)
 *   aarch64-linux-gnu-gcc <same flags> fmi_host.c -o fmi_host -ldl   (run: qemu-aarch64 -L /usr/aarch64-linux-gnu)
 * Under wine, pass Windows paths (Z:\tmp\...); the resource URI is made from FMU_DIR.
 */
#if defined(_WIN32)
#define __USE_MINGW_ANSI_STDIO 1 /* correctly rounded printf (%.17g round-trips) */
#include <windows.h>
#else
#define _POSIX_C_SOURCE 200809L
#include <dlfcn.h>
#endif
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2FunctionTypes.h"
#include "fmi3FunctionTypes.h"

#if defined(__MINGW32__)
#define STRTOD __mingw_strtod /* correctly rounded, unlike msvcrt's strtod */
#else
#define STRTOD strtod
#endif

#define MAX_VARS 256
#define MAX_LINE 65536

typedef struct {
    char type;              /* 'r', 'i' or 'b' */
    unsigned int vr;
    const char *label;      /* as given on the command line, e.g. "r13" */
    double value;           /* -p value or the current CSV value */
} Var;

typedef void (*Proc)(void);

typedef struct {
    int version;
    void *instance;
#if defined(_WIN32)
    HMODULE lib;
#else
    void *lib;
#endif
    fmi2InstantiateTYPE *fmi2Instantiate;
    fmi2SetupExperimentTYPE *fmi2SetupExperiment;
    fmi2EnterInitializationModeTYPE *fmi2EnterInitializationMode;
    fmi2ExitInitializationModeTYPE *fmi2ExitInitializationMode;
    fmi2SetRealTYPE *fmi2SetReal;
    fmi2SetIntegerTYPE *fmi2SetInteger;
    fmi2SetBooleanTYPE *fmi2SetBoolean;
    fmi2GetRealTYPE *fmi2GetReal;
    fmi2GetIntegerTYPE *fmi2GetInteger;
    fmi2GetBooleanTYPE *fmi2GetBoolean;
    fmi2DoStepTYPE *fmi2DoStep;
    fmi2GetBooleanStatusTYPE *fmi2GetBooleanStatus;
    fmi2TerminateTYPE *fmi2Terminate;
    fmi2FreeInstanceTYPE *fmi2FreeInstance;
    fmi3InstantiateCoSimulationTYPE *fmi3InstantiateCoSimulation;
    fmi3EnterInitializationModeTYPE *fmi3EnterInitializationMode;
    fmi3ExitInitializationModeTYPE *fmi3ExitInitializationMode;
    fmi3SetFloat64TYPE *fmi3SetFloat64;
    fmi3SetInt32TYPE *fmi3SetInt32;
    fmi3SetBooleanTYPE *fmi3SetBoolean;
    fmi3GetFloat64TYPE *fmi3GetFloat64;
    fmi3GetInt32TYPE *fmi3GetInt32;
    fmi3GetBooleanTYPE *fmi3GetBoolean;
    fmi3DoStepTYPE *fmi3DoStep;
    fmi3TerminateTYPE *fmi3Terminate;
    fmi3FreeInstanceTYPE *fmi3FreeInstance;
} Fmu;

static const char *program = "fmi_host";
static Fmu fmu;

static void usage(const char *fmt, ...)
{
    va_list args;
    fprintf(stderr, "%s: ", program);
    va_start(args, fmt);
    vfprintf(stderr, fmt, args);
    va_end(args);
    fprintf(stderr, "\nusage: %s [-p VAR=VALUE]... [-i VAR]... [-o VAR]... [-c FILE] [-s START] [-r TOL] [-l] "
                    "FMU_DIR VERSION BINARY TOKEN STEP STEPS\n(VAR: r<vr> Real, i<vr> Integer, b<vr> Boolean)\n",
            program);
    exit(2);
}

static void fail(const char *fmt, ...)
{
    va_list args;
    fprintf(stderr, "%s: ", program);
    va_start(args, fmt);
    vfprintf(stderr, fmt, args);
    va_end(args);
    fputc('\n', stderr);
    exit(1);
}

static const char *status_name(int status)
{
    static const char *names[] = {"OK", "Warning", "Discard", "Error", "Fatal", "Pending"};
    return status >= 0 && status <= (fmu.version == 2 ? 5 : 4) ? names[status] : "an unknown status";
}

/* OK passes, Warning is reported and passes, anything else ends the run naming the call. */
static void check(int status, const char *call, double t)
{
    if (status == 0) return;
    if (status == 1) {
        fprintf(stderr, "%s: %s at t = %.17g returned Warning\n", program, call, t);
        return;
    }
    fail("%s at t = %.17g returned %s", call, t, status_name(status));
}

static void fmi2_logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                        fmi2String message, ...)
{
    va_list args;
    (void)env;
    fprintf(stderr, "[%s] %s %s: ", name ? name : "?", status_name((int)status), category ? category : "");
    va_start(args, message);
    vfprintf(stderr, message ? message : "", args);
    va_end(args);
    fputc('\n', stderr);
}

static void fmi3_logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env;
    fprintf(stderr, "[fmu] %s %s: %s\n", status_name((int)status), category ? category : "",
            message ? message : "");
}

static const fmi2CallbackFunctions fmi2_callbacks = {fmi2_logger, calloc, free, NULL, NULL};

/* ---- loading the binary -------------------------------------------------------------------- */

static void open_library(const char *path)
{
#if defined(_WIN32)
    fmu.lib = LoadLibraryA(path);
    if (fmu.lib == NULL) fail("LoadLibrary(%s) failed with Windows error %lu", path, (unsigned long)GetLastError());
#else
    fmu.lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (fmu.lib == NULL) fail("dlopen(%s) failed: %s", path, dlerror());
#endif
}

static Proc symbol(const char *name)
{
    Proc p;
#if defined(_WIN32)
    p = (Proc)GetProcAddress(fmu.lib, name);
#else
    void *address = dlsym(fmu.lib, name);
    memcpy(&p, &address, sizeof p);
#endif
    if (p == NULL) fail("the binary does not export %s", name);
    return p;
}

static void close_library(void)
{
#if defined(_WIN32)
    FreeLibrary(fmu.lib);
#else
    dlclose(fmu.lib);
#endif
}

#define LOAD(name) fmu.name = (name##TYPE *)symbol(#name)

static void load_functions(void)
{
    if (fmu.version == 2) {
        LOAD(fmi2Instantiate); LOAD(fmi2SetupExperiment); LOAD(fmi2EnterInitializationMode);
        LOAD(fmi2ExitInitializationMode); LOAD(fmi2SetReal); LOAD(fmi2SetInteger); LOAD(fmi2SetBoolean);
        LOAD(fmi2GetReal); LOAD(fmi2GetInteger); LOAD(fmi2GetBoolean); LOAD(fmi2DoStep);
        LOAD(fmi2GetBooleanStatus); LOAD(fmi2Terminate); LOAD(fmi2FreeInstance);
    } else {
        LOAD(fmi3InstantiateCoSimulation); LOAD(fmi3EnterInitializationMode); LOAD(fmi3ExitInitializationMode);
        LOAD(fmi3SetFloat64); LOAD(fmi3SetInt32); LOAD(fmi3SetBoolean); LOAD(fmi3GetFloat64);
        LOAD(fmi3GetInt32); LOAD(fmi3GetBoolean); LOAD(fmi3DoStep); LOAD(fmi3Terminate); LOAD(fmi3FreeInstance);
    }
}

/* ---- parsing ----------------------------------------------------------------------------- */

static int parse_double(const char *text, double *value)
{
    char *end;
    while (*text == ' ' || *text == '\t') text++;
    if (*text == '\0') return 0;
    errno = 0;
    *value = STRTOD(text, &end);
    if (end == text) return 0;
    while (*end == ' ' || *end == '\t') end++;
    return *end == '\0';
}

static void parse_var(const char *text, Var *var, int with_value)
{
    char *end;
    unsigned long vr;
    const char *eq = strchr(text, '=');
    if (text[0] != 'r' && text[0] != 'i' && text[0] != 'b')
        usage("variable '%s' must start with r (Real), i (Integer) or b (Boolean)", text);
    if (with_value != (eq != NULL)) usage(with_value ? "-p needs VAR=VALUE, got '%s'" : "'%s': no =VALUE here", text);
    if (!(text[1] >= '0' && text[1] <= '9')) usage("variable '%s' has no value reference", text);
    errno = 0;
    vr = strtoul(text + 1, &end, 10);
    if (errno != 0 || vr > 0xFFFFFFFFul || end != (eq ? eq : text + strlen(text)))
        usage("variable '%s' has no valid value reference", text);
    var->type = text[0];
    var->vr = (unsigned int)vr;
    var->label = text;
    var->value = 0.0;
    if (eq != NULL && !parse_double(eq + 1, &var->value)) usage("-p %s: '%s' is not a number", text, eq + 1);
}

static int parse_count(const char *text, const char *what)
{
    char *end;
    long n;
    errno = 0;
    n = strtol(text, &end, 10);
    if (errno != 0 || end == text || *end != '\0' || n < 0 || n > INT_MAX) usage("%s must be a count, got '%s'", what, text);
    return (int)n;
}

static double parse_number(const char *text, const char *what)
{
    double value;
    if (!parse_double(text, &value) || !isfinite(value)) usage("%s must be a finite number, got '%s'", what, text);
    return value;
}

/* ---- setting and getting one variable ---------------------------------------------------- */

static void set_var(const Var *var, double t)
{
    char call[64];
    int status;
    if (var->type != 'r' && !(var->value == floor(var->value) && var->value >= -2147483648.0 &&
                              var->value <= 2147483647.0))
        fail("%s: %.17g at t = %.17g is not a 32-bit integer", var->label, var->value, t);
    if (var->type == 'b' && var->value != 0.0 && var->value != 1.0)
        fail("%s: %.17g at t = %.17g is not a Boolean (0 or 1)", var->label, var->value, t);
    if (fmu.version == 2) {
        fmi2ValueReference vr = var->vr;
        if (var->type == 'r') {
            fmi2Real v = var->value;
            status = fmu.fmi2SetReal(fmu.instance, &vr, 1, &v);
            sprintf(call, "fmi2SetReal(vr %u)", var->vr);
        } else if (var->type == 'i') {
            fmi2Integer v = (fmi2Integer)var->value;
            status = fmu.fmi2SetInteger(fmu.instance, &vr, 1, &v);
            sprintf(call, "fmi2SetInteger(vr %u)", var->vr);
        } else {
            fmi2Boolean v = var->value != 0.0 ? fmi2True : fmi2False;
            status = fmu.fmi2SetBoolean(fmu.instance, &vr, 1, &v);
            sprintf(call, "fmi2SetBoolean(vr %u)", var->vr);
        }
    } else {
        fmi3ValueReference vr = var->vr;
        if (var->type == 'r') {
            fmi3Float64 v = var->value;
            status = fmu.fmi3SetFloat64(fmu.instance, &vr, 1, &v, 1);
            sprintf(call, "fmi3SetFloat64(vr %u)", var->vr);
        } else if (var->type == 'i') {
            fmi3Int32 v = (fmi3Int32)var->value;
            status = fmu.fmi3SetInt32(fmu.instance, &vr, 1, &v, 1);
            sprintf(call, "fmi3SetInt32(vr %u)", var->vr);
        } else {
            fmi3Boolean v = var->value != 0.0;
            status = fmu.fmi3SetBoolean(fmu.instance, &vr, 1, &v, 1);
            sprintf(call, "fmi3SetBoolean(vr %u)", var->vr);
        }
    }
    check(status, call, t);
}

static void print_var(const Var *var, double t)
{
    char call[64];
    int status;
    if (fmu.version == 2) {
        fmi2ValueReference vr = var->vr;
        if (var->type == 'r') {
            fmi2Real v = 0.0;
            status = fmu.fmi2GetReal(fmu.instance, &vr, 1, &v);
            sprintf(call, "fmi2GetReal(vr %u)", var->vr);
            check(status, call, t);
            printf(",%.17g", v);
        } else if (var->type == 'i') {
            fmi2Integer v = 0;
            status = fmu.fmi2GetInteger(fmu.instance, &vr, 1, &v);
            sprintf(call, "fmi2GetInteger(vr %u)", var->vr);
            check(status, call, t);
            printf(",%d", (int)v);
        } else {
            fmi2Boolean v = fmi2False;
            status = fmu.fmi2GetBoolean(fmu.instance, &vr, 1, &v);
            sprintf(call, "fmi2GetBoolean(vr %u)", var->vr);
            check(status, call, t);
            printf(",%d", v ? 1 : 0);
        }
    } else {
        fmi3ValueReference vr = var->vr;
        if (var->type == 'r') {
            fmi3Float64 v = 0.0;
            status = fmu.fmi3GetFloat64(fmu.instance, &vr, 1, &v, 1);
            sprintf(call, "fmi3GetFloat64(vr %u)", var->vr);
            check(status, call, t);
            printf(",%.17g", v);
        } else if (var->type == 'i') {
            fmi3Int32 v = 0;
            status = fmu.fmi3GetInt32(fmu.instance, &vr, 1, &v, 1);
            sprintf(call, "fmi3GetInt32(vr %u)", var->vr);
            check(status, call, t);
            printf(",%d", (int)v);
        } else {
            fmi3Boolean v = 0;
            status = fmu.fmi3GetBoolean(fmu.instance, &vr, 1, &v, 1);
            sprintf(call, "fmi3GetBoolean(vr %u)", var->vr);
            check(status, call, t);
            printf(",%d", v ? 1 : 0);
        }
    }
}

static void print_row(const Var *outputs, int n_outputs, double t)
{
    int j;
    printf("%.17g", t);
    for (j = 0; j < n_outputs; j++) print_var(&outputs[j], t);
    putchar('\n');
}

/* ---- the input CSV ---------------------------------------------------------------------- */

typedef struct {
    FILE *file;
    const char *path;
    long line;
    long rows;
} Csv;

/* Reads the next data row into the inputs' values; returns 0 at the end of the file. */
static int read_row(Csv *csv, Var *inputs, int n_inputs)
{
    static char buffer[MAX_LINE];
    for (;;) {
        char *field, *next;
        size_t length;
        int j;
        double first;
        if (fgets(buffer, sizeof buffer, csv->file) == NULL) {
            if (ferror(csv->file)) fail("reading %s failed", csv->path);
            return 0;
        }
        csv->line++;
        length = strlen(buffer);
        if (length == sizeof buffer - 1 && buffer[length - 1] != '\n')
            fail("%s:%ld: line longer than %d characters", csv->path, csv->line, MAX_LINE - 2);
        while (length > 0 && (buffer[length - 1] == '\n' || buffer[length - 1] == '\r')) buffer[--length] = '\0';
        next = strchr(buffer, ',');
        if (next) *next = '\0';
        if (csv->line == 1 && !parse_double(buffer, &first)) continue; /* a header */
        if (next) *next = ',';
        field = buffer;
        for (j = 0; j < n_inputs; j++) {
            next = strchr(field, ',');
            if (next) *next = '\0';
            if (!parse_double(field, &inputs[j].value))
                fail("%s:%ld: column %d (%s) is not a number: '%s'", csv->path, csv->line, j + 1, inputs[j].label,
                     field);
            if (next == NULL) {
                if (j + 1 < n_inputs)
                    fail("%s:%ld: %d columns, %d inputs given with -i", csv->path, csv->line, j + 1, n_inputs);
                break;
            }
            field = next + 1;
        }
        if (next != NULL) fail("%s:%ld: more columns than the %d inputs given with -i", csv->path, csv->line, n_inputs);
        csv->rows++;
        return 1;
    }
}

/* ---- the run ----------------------------------------------------------------------------- */

/* file:// URI (FMI 2) or native path with a trailing separator (FMI 3) of FMU_DIR/resources. */
static char *resource_location(const char *dir)
{
    static const char hex[] = "0123456789ABCDEF";
    size_t n = strlen(dir), i, k = 0;
    char *out = malloc(3 * n + 32);
    if (out == NULL) fail("out of memory");
    if (fmu.version == 3) {
#if defined(_WIN32)
        sprintf(out, "%s\\resources\\", dir);
#else
        sprintf(out, "%s/resources/", dir);
#endif
        return out;
    }
    k += (size_t)sprintf(out, dir[0] == '/' ? "file://" : "file:///");
    for (i = 0; i < n; i++) {
        unsigned char c = (unsigned char)dir[i];
        if (c == '\\') c = '/';
        if ((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || strchr("/-._~:", c)) {
            out[k++] = (char)c;
        } else {
            out[k++] = '%';
            out[k++] = hex[c >> 4];
            out[k++] = hex[c & 15];
        }
    }
    strcpy(out + k, "/resources");
    return out;
}

int main(int argc, char **argv)
{
    static Var params[MAX_VARS], inputs[MAX_VARS], outputs[MAX_VARS];
    int n_params = 0, n_inputs = 0, n_outputs = 0, logging = 0, steps, k, j, a;
    double start = 0.0, step, tolerance = 0.0, t, t_next, stop;
    int tolerance_defined = 0, terminated = 0;
    const char *csv_path = NULL, *positional[6];
    int n_positional = 0;
    char *resources;
    Csv csv = {NULL, NULL, 0, 0};

    for (a = 1; a < argc; a++) {
        const char *arg = argv[a];
        if (arg[0] == '-' && arg[1] != '\0' && arg[2] == '\0' && strchr("piocsrl", arg[1])) {
            if (arg[1] == 'l') { logging = 1; continue; }
            if (a + 1 >= argc) usage("%s needs a value", arg);
            a++;
            switch (arg[1]) {
            case 'p':
                if (n_params == MAX_VARS) usage("more than %d -p", MAX_VARS);
                parse_var(argv[a], &params[n_params++], 1);
                break;
            case 'i':
                if (n_inputs == MAX_VARS) usage("more than %d -i", MAX_VARS);
                parse_var(argv[a], &inputs[n_inputs++], 0);
                break;
            case 'o':
                if (n_outputs == MAX_VARS) usage("more than %d -o", MAX_VARS);
                parse_var(argv[a], &outputs[n_outputs++], 0);
                break;
            case 'c': csv_path = argv[a]; break;
            case 's': start = parse_number(argv[a], "-s START"); break;
            default:
                tolerance = parse_number(argv[a], "-r TOL");
                tolerance_defined = 1;
                break;
            }
        } else if (n_positional < 6) {
            positional[n_positional++] = arg;
        } else {
            usage("unexpected argument '%s'", arg);
        }
    }
    if (n_positional != 6) usage("expected 6 arguments after the options, got %d", n_positional);
    if (strcmp(positional[1], "2") == 0) fmu.version = 2;
    else if (strcmp(positional[1], "3") == 0) fmu.version = 3;
    else usage("VERSION must be 2 or 3, got '%s'", positional[1]);
    step = parse_number(positional[4], "STEP");
    if (!(step > 0.0)) usage("STEP must be positive, got '%s'", positional[4]);
    steps = parse_count(positional[5], "STEPS");
    if (n_inputs > 0 && csv_path == NULL) usage("-i needs the input CSV of -c");
    if (n_inputs == 0 && csv_path != NULL) usage("-c without any -i column");
    if (csv_path != NULL) {
        csv.path = csv_path;
        csv.file = fopen(csv_path, "r");
        if (csv.file == NULL) usage("cannot open the input CSV %s: %s", csv_path, strerror(errno));
        if (!read_row(&csv, inputs, n_inputs)) fail("%s has no data row", csv_path);
    }
    stop = start + (double)steps * step;

    open_library(positional[2]);
    load_functions();
    resources = resource_location(positional[0]);
    if (fmu.version == 2) {
        fmu.instance = fmu.fmi2Instantiate("fmi_host", fmi2CoSimulation, positional[3], resources, &fmi2_callbacks,
                                           fmi2False, logging ? fmi2True : fmi2False);
        if (fmu.instance == NULL) fail("fmi2Instantiate returned NULL (token %s)", positional[3]);
        check(fmu.fmi2SetupExperiment(fmu.instance, tolerance_defined, tolerance, start, fmi2True, stop),
              "fmi2SetupExperiment", start);
        for (j = 0; j < n_params; j++) set_var(&params[j], start);
        check(fmu.fmi2EnterInitializationMode(fmu.instance), "fmi2EnterInitializationMode", start);
        for (j = 0; j < n_inputs; j++) set_var(&inputs[j], start);
        check(fmu.fmi2ExitInitializationMode(fmu.instance), "fmi2ExitInitializationMode", start);
    } else {
        fmu.instance = fmu.fmi3InstantiateCoSimulation("fmi_host", positional[3], resources, 0, logging ? 1 : 0, 0, 0,
                                                       NULL, 0, NULL, fmi3_logger, NULL);
        if (fmu.instance == NULL) fail("fmi3InstantiateCoSimulation returned NULL (token %s)", positional[3]);
        for (j = 0; j < n_params; j++) set_var(&params[j], start);
        check(fmu.fmi3EnterInitializationMode(fmu.instance, tolerance_defined, tolerance, start, 1, stop),
              "fmi3EnterInitializationMode", start);
        for (j = 0; j < n_inputs; j++) set_var(&inputs[j], start);
        check(fmu.fmi3ExitInitializationMode(fmu.instance), "fmi3ExitInitializationMode", start);
    }

    printf("time");
    for (j = 0; j < n_outputs; j++) printf(",%s", outputs[j].label);
    putchar('\n');
    print_row(outputs, n_outputs, start);
    for (k = 0; k < steps && !terminated; k++) {
        t = start + (double)k * step;
        t_next = start + (double)(k + 1) * step;
        if (k > 0 && n_inputs > 0 && !read_row(&csv, inputs, n_inputs))
            fail("%s has %ld data rows; %d steps need %d", csv.path, csv.rows, steps, steps);
        for (j = 0; j < n_inputs; j++) set_var(&inputs[j], t);
        if (fmu.version == 2) {
            int status = fmu.fmi2DoStep(fmu.instance, t, t_next - t, fmi2True);
            if (status == fmi2Discard) {
                fmi2Boolean stop_asked = fmi2False;
                check(fmu.fmi2GetBooleanStatus(fmu.instance, fmi2Terminated, &stop_asked),
                      "fmi2GetBooleanStatus(fmi2Terminated)", t);
                if (!stop_asked) check(status, "fmi2DoStep", t);
                terminated = 1;
            } else {
                check(status, "fmi2DoStep", t);
            }
        } else {
            fmi3Boolean event = 0, stop_asked = 0, early = 0;
            fmi3Float64 last = t;
            int status = fmu.fmi3DoStep(fmu.instance, t, t_next - t, 1, &event, &stop_asked, &early, &last);
            if (!(stop_asked && status == fmi3Discard)) check(status, "fmi3DoStep", t);
            if (early && !stop_asked) fail("fmi3DoStep at t = %.17g returned early (not requested)", t);
            if (stop_asked && status != fmi3Discard && !early) print_row(outputs, n_outputs, t_next);
            terminated = stop_asked;
        }
        if (terminated) fprintf(stderr, "%s: the FMU asked to terminate in the step from t = %.17g\n", program, t);
        else print_row(outputs, n_outputs, t_next);
    }
    t = start + (double)k * step;
    if (fmu.version == 2) {
        check(fmu.fmi2Terminate(fmu.instance), "fmi2Terminate", t);
        fmu.fmi2FreeInstance(fmu.instance);
    } else {
        check(fmu.fmi3Terminate(fmu.instance), "fmi3Terminate", t);
        fmu.fmi3FreeInstance(fmu.instance);
    }
    close_library();
    free(resources);
    if (csv.file) fclose(csv.file);
    if (fflush(stdout) != 0 || ferror(stdout)) fail("writing the output failed");
    return 0;
}
