"""Toy FMU for the orchestrator's tests: records what it was given.

Inputs u, w; at each fmi2DoStep: last_u = u, last_w = w, acc += u * h, calls += 1.
u_sets counts the fmi2SetReal calls that reached u. Parameters of each FMI type are
echoed as Real outputs (echo_gain, echo_count, echo_flag, echo_label_len). With
fail_at = k > 0, the k-th fmi2DoStep returns False (a failed step, no exception). With
raise_at = k > 0, the k-th fmi2DoStep raises an exception (pythonfmu 0.7.0 reports it as
fmi2Fatal with the exception's repr in the log; the instance is gone after that).
"""

from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real, String
from pythonfmu.enums import Fmi2Status


class ToySink(Fmi2Slave):
    author = "pmsm-ev-cosim tests"
    description = "records its inputs at each step; echoes its parameters"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.u = 0.0
        self.w = 0.0
        self.gain = 1.0
        self.count = 0
        self.flag = False
        self.label = "x"
        self.fail_at = 0
        self.raise_at = 0
        for name in ("last_u", "last_w", "acc", "calls", "last_t", "last_h", "u_sets",
                     "echo_gain", "echo_count", "echo_flag", "echo_label_len"):
            setattr(self, name, 0.0)
        self.register_variable(Real("u", causality=Fmi2Causality.input, start=0.0, setter=self._set_u))
        self.register_variable(Real("w", causality=Fmi2Causality.input, start=0.0))
        self.register_variable(Real("gain", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))
        self.register_variable(Integer("count", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))
        self.register_variable(Boolean("flag", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))
        self.register_variable(Integer("fail_at", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))
        self.register_variable(Integer("raise_at", causality=Fmi2Causality.parameter,
                                       variability=Fmi2Variability.fixed))
        self.register_variable(String("label", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))
        for name in ("last_u", "last_w", "acc", "calls", "last_t", "last_h", "u_sets",
                     "echo_gain", "echo_count", "echo_flag", "echo_label_len"):
            self.register_variable(Real(name, causality=Fmi2Causality.output))

    def _set_u(self, value):
        self.u = value
        self.u_sets += 1.0

    def exit_initialization_mode(self):
        self.echo_gain = float(self.gain)
        self.echo_count = float(self.count)
        self.echo_flag = 1.0 if self.flag else 0.0
        self.echo_label_len = float(len(self.label))

    def do_step(self, current_time, step_size):
        if self.raise_at and self.calls + 1 >= self.raise_at:
            raise RuntimeError(f"toy failure: step {self.raise_at} raises on purpose")
        if self.fail_at and self.calls + 1 >= self.fail_at:
            self.log(f"step {self.fail_at} fails on purpose", Fmi2Status.error)
            return False
        self.last_u = self.u
        self.last_w = self.w
        self.acc += self.gain * self.u * step_size
        self.calls += 1.0
        self.last_t = current_time
        self.last_h = step_size
        return True
