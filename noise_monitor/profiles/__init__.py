"""Camera profiles from what users have: an EMVA 1288 datasheet (:mod:`.emva`) or a photon-transfer
recording of the camera (:mod:`.characterize`, simulated by the ``ptc`` scenario of :mod:`.ptc_sim`)."""
from .datasheet import Datasheet, DatasheetError, load_datasheet
from .emva import ProfileResult, predict_datasheet, profile_from_datasheet, round_trip

__all__ = ["Datasheet", "DatasheetError", "ProfileResult", "load_datasheet", "predict_datasheet",
           "profile_from_datasheet", "round_trip"]
