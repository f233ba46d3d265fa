"""Response prediction: the (updated) model driven by the measured input of an event, with
uncertainty, at measured and unmeasured floors (docs/predict.md, docs/interfaces.md §7).

- :mod:`.config`  settings (:class:`PredictConfig`);
- :mod:`.record`  an event window as input records and measured outputs;
- :mod:`.draws`   parameter draws and the model-error level of a posterior;
- :mod:`.batch`   many draws through the exact solver of :mod:`shm_ros.core.response` at once;
- :mod:`.signals` onset, baseline, strong motion, NRMS;
- :mod:`.predict` one event: mean, band, peaks, scores;
- :mod:`.scores`  Table 3 and the JSON of ``prediction.json``.
"""

from shm_ros.core.response.batch import batch_responses

from .config import Baseline, PredictConfig, Unmeasured
from .draws import PosteriorDraws, draws_from_posterior, nominal_draws
from .predict import ChannelPrediction, EventPrediction, predict_event, prediction_outputs
from .record import EventRecord, event_from_window
from .scores import event_json, format_table3, summary_json, table3_row

__all__ = ["Baseline", "ChannelPrediction", "EventPrediction", "EventRecord", "PosteriorDraws", "PredictConfig",
           "batch_responses", "draws_from_posterior", "event_from_window", "event_json", "format_table3",
           "Unmeasured", "nominal_draws", "predict_event", "prediction_outputs", "summary_json", "table3_row"]
