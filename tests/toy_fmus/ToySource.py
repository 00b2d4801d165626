"""Toy FMU for the orchestrator's tests: y = slope * (number of do_step calls).

Outputs after k steps: y = slope * k, calls = k, last_t / last_h = the arguments of the
last fmi2DoStep. No exceptions (a plain pythonfmu FMU must not raise, see the tests).
"""

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real


class ToySource(Fmi2Slave):
    author = "pmsm-ev-cosim tests"
    description = "y = slope * (number of steps taken); counts its steps"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.slope = 1.0
        self.y = 0.0
        self.calls = 0.0
        self.last_t = -1.0
        self.last_h = -1.0
        self.n_steps = 0
        self.register_variable(Real("slope", causality=Fmi2Causality.parameter,
                                    variability=Fmi2Variability.fixed))
        for name in ("y", "calls", "last_t", "last_h"):
            self.register_variable(Real(name, causality=Fmi2Causality.output))
        self.register_variable(Integer("n_steps", causality=Fmi2Causality.output,
                                       variability=Fmi2Variability.discrete))

    def do_step(self, current_time, step_size):
        self.calls += 1.0
        self.n_steps += 1
        self.y = self.slope * self.calls
        self.last_t = current_time
        self.last_h = step_size
        return True
