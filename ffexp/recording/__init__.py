"""Run recordings: one MCAP file per run (see :mod:`ffexp.recording.topics`).

In a notebook::

    import ffexp
    rec = ffexp.recording.load("runs/method1_case1-....mcap")
    df = rec.frame("/estimator/state")   # pandas: t_s, log_time_ns, wrench_0 .. wrench_5, ...
"""

from ffexp.recording.reader import JsonData, Recording, RecoverResult, TopicData, load, recover
from ffexp.recording.recorder import Recorder

__all__ = [
    "JsonData",
    "Recorder",
    "Recording",
    "RecoverResult",
    "TopicData",
    "load",
    "recover",
]
