"""Model-independent measurements shared by the lab and the live monitor."""
from .temporal import BlockTemporal, block_temporal, global_shift, static_runs

__all__ = ["BlockTemporal", "block_temporal", "global_shift", "static_runs"]
