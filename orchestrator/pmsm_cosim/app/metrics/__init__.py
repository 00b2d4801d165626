"""The drive's figures of merit and the policy that judges them (docs/architecture.md, "Physics and policy").

Computed from the recorded columns of the result contract (``pmsm_ev.results``: the columns, the angle
error, eq 31's load torque, the energy bookkeeping), on arrays; no FMI, no files, no plotting. One module
per subject, each with its own bands, thresholds and windows beside the figures that use them:

* ``run``: ``compute_metrics``, a run's metrics.json (speed and angle errors, plateaus, elevation steps
  and their settling into ``SETTLING_BAND``), with the blocks below the run's columns allow;
* ``sensorless``: the sensorless unit's modes, handovers and start-up (``STARTUP_BAND``, ``ROLL_BACK_LIMIT``);
* ``synchronism``: did the drive keep the car (``SYNC_BAND``, ``SYNC_REL``, ``RECOVERY_BAND``, ...) and the
  synchronism matrix's targets (``ROLL_BACK_EXTRA`` by strategy, ``SPEED_EXTRA``, ``SPIN_LIMIT``, ``RECOVERY_LIMIT``);
* ``speed_range``: where the car fell behind the driver (``BEHIND_BAND_KMH``) and the acceleration figures;
* ``trace``: a drive cycle's tolerance band (``TRACE_BAND_KMH``, ``EPA_BAND_KMH``) and how a run kept to it;
* ``energy``: Wh/km and the battery's figures on the plant's energy bookkeeping (``ENERGY_MIN_DISTANCE``);
* ``cycle_energy``: energy per phase of a drive cycle and the balance and wheel checks (``BALANCE_TOL``,
  ``WHEEL_TOL``);
* ``windows``: figures of a window of rows (after a time, under a mask, per plateau) for compare, the
  reports and the robustness maps, and a run's timing from its metrics.json;
* ``summary``: one number per figure of merit, for sweeps' tables (``SUMMARY_METRICS``);
* ``verdicts``: the failure rule of a drive-cycle sample (``INSIDE_MIN``, ``REASONS``) and the unseen slip;
* ``rows``: the helpers they share (RMS, runs of True, the driver's direction, roll-back, km/h) and where the
  "after" figures start (``T_FROM``).
"""
