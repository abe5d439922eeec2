"""Run recordings: one MCAP file per run (see :mod:`ffexp.recording.topics`)."""

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
