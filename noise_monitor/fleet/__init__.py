"""Field campaigns at fleet scale: many bags replayed through the monitor (Ray or a local process pool),
a resumable manifest and a campaign report (``noise-monitor campaign``)."""
from .campaign import run_campaign

__all__ = ["run_campaign"]
