/*
 * stair3.c - a Stair-like FMI 3.0 test model with time events (duffid's own code): the output
 * counter rises by one at every multiple of the parameter period. With eventModeUsed the FMU asks
 * for Event Mode (eventHandlingNeeded) after a step that reached an event and counts it in
 * event_updates when the importer updates it there; otherwise it updates inside doStep.
 */
#include "typed_fmu.h"
#include "typed_model.h"

void model_initialize(Model *m) { ((double *)model_values(m, V_next_tick))[0] = *(double *)model_values(m, V_period); }
void model_calculate(Model *m) { (void)m; }
void model_step(Model *m, double h)
{
    (void)m;
    (void)h;
}

int model_event_due(Model *m)
{
    double next = *(double *)model_values(m, V_next_tick), period = *(double *)model_values(m, V_period);
    return model_time(m) >= next - 1e-9 * period;
}

void model_update(Model *m, int in_event_mode)
{
    *(double *)model_values(m, V_next_tick) += *(double *)model_values(m, V_period);
    *(int *)model_values(m, V_counter) += 1;
    if (in_event_mode) *(int *)model_values(m, V_event_updates) += 1;
}
