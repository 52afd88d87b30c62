/*
 * duffid_build.h - the build configuration of the estimator core: empty here.
 *
 * The core (duffid_estimator.c) runs the models it describes itself (DUFFID_DUFFING1/2) and,
 * when DUFFID_GENERATED_MODEL is defined, the generated description compiled in with it
 * (duffid_model.h). A build whose compiler flags cannot carry -DDUFFID_GENERATED_MODEL
 * replaces this file with one that defines it: an estimator FMU of a chain or of the user's
 * own equations ships such a copy in its sources/, so that any tool that rebuilds the FMU
 * from its file list (`fmpy compile`: FMI 2 lists no preprocessor definitions) compiles
 * the core for the FMU's model (duffid.fmu.estimator).
 */
#ifndef DUFFID_BUILD_H
#define DUFFID_BUILD_H
#endif /* DUFFID_BUILD_H */
