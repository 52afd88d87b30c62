"""A pythonfmu test FMU: outputs its inputs, one of discrete and one of continuous variability."""
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class Echo(Fmi2Slave):
    """y_discrete = u_discrete, y_continuous = u_continuous (the values set for the step)."""

    author = "duffid tests"
    description = "echoes a discrete and a continuous Real input"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.u_discrete = self.u_continuous = self.y_discrete = self.y_continuous = 0.0
        self.register_variable(Real("u_discrete", causality=Fmi2Causality.input, variability=Fmi2Variability.discrete))
        self.register_variable(Real("u_continuous", causality=Fmi2Causality.input))
        self.register_variable(Real("y_discrete", causality=Fmi2Causality.output, variability=Fmi2Variability.discrete))
        self.register_variable(Real("y_continuous", causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        self.y_discrete, self.y_continuous = self.u_discrete, self.u_continuous
        return True
