/* The description of one container FMU, as the tables of its generated header
 * container_fmu_config.h (written by duffid.cosim.container): the components, the
 * connections between them and the mapping of the container's variables to theirs.
 *
 * The container's own variables (names, start values, causality, variability, types) are the
 * usual tables of the shared glue (fmus/common/fmu_model.h); value reference 0 is the time.
 * Types are the glue's VARTYPE_* codes (Float64, Integer/Int32, Boolean).
 */
#ifndef DUFFID_CONTAINER_H
#define DUFFID_CONTAINER_H

#include <stdint.h>

/* A component: an FMU unpacked in resources/<name>/ of the container. */
typedef struct {
    const char *name;              /* component name (and its folder in resources/) */
    const char *fmu;               /* the FMU file it came from, for messages */
    const char *model_identifier;  /* its binary: binaries/<platform>/<model_identifier><suffix> */
    int fmi_version;               /* 2 or 3 (co-simulation) */
    const char *token;             /* guid / instantiationToken */
} ContainerComponent;

/* The connection sources, sorted by (component, type): each one value read after every
 * internal step into slot `slot` of the buffer of its type (Float64, or Integer/Boolean). */
typedef struct {
    int component;
    unsigned vr;
    int type;
    int slot;
} ContainerSource;

/* The connection targets, sorted by (component, type): set from slot `slot` of the buffer of
 * their type after every internal step (and from zeros during initialisation, as the
 * orchestrator does). */
typedef struct {
    int component;
    unsigned vr;
    int type;
    intptr_t slot;
} ContainerTarget;

/* A container variable and one component variable it maps to: an input or parameter is set
 * into each of its targets, an output read from its one source. */
typedef struct {
    unsigned container_vr;
    int component;
    unsigned vr;
} ContainerLink;

#endif
