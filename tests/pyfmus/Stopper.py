"""A pythonfmu test FMU: y = time; it asks to end the simulation at the step that reaches t_end."""
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class Stopper(Fmi2Slave):
    """y = time; doStep returns Discard with the terminated status from t_end on."""

    author = "duffid tests"
    description = "asks to end the simulation at t_end"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.y = 0.0
        self.t_end = 0.35
        self.register_variable(Real("y", causality=Fmi2Causality.output))
        self.register_variable(Real("t_end", causality=Fmi2Causality.parameter,
                                    variability=Fmi2Variability.tunable))

    def do_step(self, current_time, step_size):
        if current_time + step_size > self.t_end + 1e-12:
            return False  # pythonfmu: Discard, terminated
        self.y = current_time + step_size
        return True
