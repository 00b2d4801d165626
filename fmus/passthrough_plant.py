"""Slave of PassThroughPlant.fmu, for the step-cost benchmark (``pmsm-cosim bench``):
PmsmEvPlant's interface, parameters and FMI plumbing, but ``do_step`` computes nothing
(the outputs keep their initial values). It measures the floor of FMI calls plus
pythonfmu under the plant's interface (with the kernels compiled: of its compiled step, computing nothing)."""

from __future__ import annotations

from pmsm_ev_fmus.pmsm_ev_plant import PmsmEvPlant


class PassThroughPlant(PmsmEvPlant):
    """PmsmEvPlant without physics in the step."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.description = ("Benchmark unit: the interface of PmsmEvPlant; fmi2DoStep computes nothing, "
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
            step = self._pass_address = self._plant._kernels.fmu_step_address("pass")
        return (step, *offer[1:])
