"""The paper's metadata sensitivity analysis: reference metadata, sweeps and the noise model's table."""
from __future__ import annotations

import numpy as np

from .metadata import CameraMetadata, factor_to_db

#: All variable metadata at their maximum, CMOS, flat image at 128 DN (the paper's setting).
REFERENCE_INTENSITY_DN = 128.0
REFERENCE_VALUES = dict(
    gain_db=float(factor_to_db(16.0)), exposure_time_s=0.2, sensor_temperature_c=80.0, dark_signal_fom_na_cm2=1.0,
    full_well_e=100_000.0, pixel_clock_hz=150e6, sense_node_gain_v_per_e=5e-6, sense_node_reset_factor=1.0,
    pixel_size_m=10e-6, thermal_white_noise_v_per_sqrt_hz=60e-9, sensor_type="cmos",
)
#: The appendix's sampled values: 10 uniform samples of each range (gain sampled as a factor).
SWEEPS: dict[str, np.ndarray] = {
    "gain_db": np.array([factor_to_db(g) for g in np.linspace(1.0, 16.0, 10)]),
    "exposure_time_s": np.linspace(0.001, 0.2, 10),
    "sensor_temperature_c": np.linspace(0.0, 80.0, 10),
    "dark_signal_fom_na_cm2": np.linspace(0.0, 1.0, 10),
    "full_well_e": np.linspace(2_000.0, 100_000.0, 10),
    "pixel_clock_hz": np.linspace(8e6, 150e6, 10),
    "sense_node_gain_v_per_e": np.linspace(1e-6, 5e-6, 10),
    "sense_node_reset_factor": np.linspace(0.0, 1.0, 10),
    "pixel_size_m": np.linspace(0.9e-6, 10e-6, 10),
    "thermal_white_noise_v_per_sqrt_hz": np.linspace(1e-9, 60e-9, 10),
}
SWEEP_INTENSITIES = np.linspace(0.0, 255.0, 10).round()

#: Paper, Table "Input-output sensitivity analysis", top half ("Noise Model"): total sigma in DN.
#: Reading (physics.md): the pixel-clock row is readout noise alone; the thermal-white-noise row is CMOS.
PAPER_NOISE_MODEL_TABLE: dict[str, list[float]] = {
    "intensity": [5.54, 9.87, 9.94, 10.0, 10.1, 10.1, 10.2, 10.2, 10.3, 6.1],
    "gain_db": [0.82, 1.86, 2.88, 3.92, 4.94, 5.96, 6.99, 8.02, 9.02, 10.1],
    "exposure_time_s": [4.02, 5.06, 5.93, 6.67, 7.35, 7.96, 8.53, 9.08, 9.60, 10.1],
    "sensor_temperature_c": [3.69, 3.76, 3.86, 4.03, 4.31, 4.77, 5.49, 6.56, 8.05, 10.1],
    "dark_signal_fom_na_cm2": [3.96, 5.02, 5.89, 6.65, 7.34, 7.95, 8.53, 9.06, 9.57, 10.1],
    "full_well_e": [118.4, 69.6, 41.4, 28.6, 21.8, 17.6, 14.8, 12.8, 11.3, 10.1],
    "pixel_clock_hz": [3.33] * 10,
    "sense_node_gain_v_per_e": [12.9, 11.7, 11.1, 10.8, 10.6, 10.4, 10.3, 10.2, 10.1, 10.1],
    "sense_node_reset_factor": [9.56, 9.56, 9.58, 9.59, 9.67, 9.71, 9.76, 9.85, 9.95, 10.1],
    "pixel_size_m": [4.05, 4.34, 4.80, 5.38, 6.05, 6.79, 7.57, 8.39, 9.21, 10.1],
    "thermal_white_noise_v_per_sqrt_hz": [10.0, 10.0, 10.0, 10.0, 10.0, 10.0, 10.0, 10.0, 10.1, 10.1],
}


def reference_metadata() -> CameraMetadata:
    return CameraMetadata.from_mapping(REFERENCE_VALUES)


def sweep_cells(row: str) -> list[tuple[float, CameraMetadata]]:
    """(intensity, metadata) of the 10 cells of one row of the table."""
    ref = reference_metadata()
    if row == "intensity":
        return [(float(v), ref) for v in SWEEP_INTENSITIES]
    return [(REFERENCE_INTENSITY_DN, ref.replace(**{row: float(v)})) for v in SWEEPS[row]]
