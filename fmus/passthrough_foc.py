"""Slave of PassThroughFoc.fmu, for the step-cost benchmark (``pmsm-cosim bench``):
FocEkf5's interface, parameters and FMI plumbing, but ``do_step`` computes nothing (the
outputs keep their initial values). It measures the floor of FMI calls plus pythonfmu
under the controller's interface (with the kernels compiled: of its compiled step, computing nothing)."""

from __future__ import annotations

from pmsm_ev_fmus.foc_slave import FocSlave


class PassThroughFoc(FocSlave):
    """FocEkf5 without observer and controller in the step."""

    def __init__(self, **kwargs):
        super().__init__("ekf5", "no computation (benchmark unit)", **kwargs)
        self.description = ("Benchmark unit: the interface of FocEkf5; fmi2DoStep computes nothing, "
                            "the outputs keep their initial values.")

    def do_step(self, current_time, step_size):
        return True

    def compiled_step(self):
        """The compiled step of the real unit's buffers, computing nothing (``pmsm_ev.kernels.fmu``, "pass"): the
        floor of the FMI calls in compiled code."""
        offer = super().compiled_step()
        if offer is None:
            return None
        step = self.__dict__.get("_pass_address")
        if step is None:
            step = self._pass_address = self._unit._kernels.fmu_step_address("pass")
        return (step, *offer[1:])
