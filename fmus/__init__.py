"""pmsm_ev_fmus (the folder ``fmus/``): FMI 2.0 co-simulation units of the drive, pythonfmu
slaves around ``pmsm_ev``, and their build (``build_all``, ``main``; see
``pmsm_ev_fmus.build``: the FMUs go to the user's cache, ``default_out_dir()``).

FMUs: ``PmsmEvPlant`` (vehicle + PMSM) and one controller-plus-observer FMU per observer,
all with one interface: ``FocEkf5`` (the paper's EKF), ``FocEkf4``, ``FocEkf5AB``,
``FocSensored`` and ``FocSensorless`` (truly sensorless from standstill: alignment, I-f start,
FOC on the stationary-frame EKF5); ``RouteProfile``, the scenario signals (road elevation and
speed reference) from a route table in its resources.
"""

from .build import (
    FMUS,
    OBSERVER_FMUS,
    ROUTE_FMU,
    BuildError,
    build_all,
    build_fmu,
    content_key,
    default_out_dir,
    main,
    takes_packaged_starts,
    write_fmu_with_starts,
    write_road_fmu,
    write_route_fmu,
)

__all__ = ["FMUS", "OBSERVER_FMUS", "ROUTE_FMU", "BuildError", "build_all", "build_fmu", "content_key",
           "default_out_dir", "main", "takes_packaged_starts", "write_fmu_with_starts", "write_road_fmu",
           "write_route_fmu"]
