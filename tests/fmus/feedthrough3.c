/*
 * feedthrough3.c - a Feedthrough-like FMI 3.0 test model (duffid's own code): every output is a copy
 * of the input or parameter that the generated table FEED pairs it with (see tests/typed_fmus.py);
 * String_input_length and Binary_input_length are the bytes of those inputs.
 */
#include <string.h>

#include "typed_fmu.h"
#include "typed_model.h"

void model_initialize(Model *m) { (void)m; }

void model_calculate(Model *m)
{
    int i;
    for (i = 0; i < N_FEED; i++) model_copy(m, FEED[i][0], FEED[i][1]);
    *(int *)model_values(m, V_String_input_length) = (int)strlen(*(char **)model_values(m, V_String_input));
    *(int *)model_values(m, V_Binary_input_length) = (int)((BinaryValue *)model_values(m, V_Binary_input))->size;
}

void model_step(Model *m, double h)
{
    (void)m;
    (void)h;
}

MODEL_WITHOUT_EVENTS
