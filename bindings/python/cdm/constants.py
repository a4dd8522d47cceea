"""Constants mirrored from include/cdm/cdm.h.

The header is the one source of truth: tests/python/test_constants.py parses it
and checks every name and value below against it, both ways.
"""
import enum

# Version of the header this binding was written against. The library actually
# loaded reports its own with cdm.version() / cdm.version_number().
CDM_VERSION_MAJOR = 1
CDM_VERSION_MINOR = 2
CDM_VERSION_PATCH = 0
CDM_VERSION_NUMBER = CDM_VERSION_MAJOR * 10000 + CDM_VERSION_MINOR * 100 + CDM_VERSION_PATCH


class Error(enum.IntEnum):
    """cdm_error: return codes (pinned values)."""
    CDM_OK = 0
    CDM_ERR_INVALID_ARG = -1
    CDM_ERR_NO_DEVICE = -2
    CDM_ERR_IO = -3
    CDM_ERR_TIMEOUT = -4
    CDM_ERR_DISCONNECTED = -5
    CDM_ERR_STALE = -6
    CDM_ERR_NO_DATA = -7
    CDM_ERR_PROTOCOL = -8
    CDM_ERR_UNSUPPORTED = -9
    CDM_ERR_NO_MEM = -10
    CDM_ERR_PARSE = -11
    CDM_ERR_NUMERIC = -12
    CDM_ERR_END_OF_STREAM = -13
    CDM_ERR_CRC = -14
    CDM_ERR_INTERNAL = -15
    CDM_ERR_CLOSED = -16  # since 1.2: a wait ended by close()


CDM_ERROR_COUNT = 17


class PoseFlag(enum.IntFlag):
    """cdm_pose_flag: bits of Pose.flags."""
    CDM_POSE_STALE = 1 << 0
    CDM_POSE_DISCONNECTED = 1 << 1
    CDM_POSE_COMPENSATED = 1 << 2
    CDM_POSE_OUT_OF_WORKSPACE = 1 << 3
    CDM_POSE_END_OF_STREAM = 1 << 4
    CDM_POSE_NO_POSITION = 1 << 5  # since 1.1


class Button(enum.IntFlag):
    """cdm_button: bits of Pose.buttons."""
    CDM_BUTTON_CLUTCH = 1 << 0
    CDM_BUTTON_AUX = 1 << 1
    CDM_BUTTON_MARK = 1 << 2


class EventKind(enum.IntEnum):
    """cdm_event_kind (since 1.1): what on_event reports."""
    CDM_EVENT_DISCONNECTED = 1
    CDM_EVENT_RECONNECTED = 2
    CDM_EVENT_STALE = 3
    CDM_EVENT_FRESH = 4
    CDM_EVENT_END_OF_STREAM = 5


class LogLevel(enum.IntEnum):
    """cdm_log_level (since 1.1): levels of cdm_set_log_fn's messages."""
    CDM_LOG_DEBUG = 0
    CDM_LOG_INFO = 1
    CDM_LOG_WARNING = 2
    CDM_LOG_ERROR = 3


class WatchKind(enum.IntEnum):
    """cdm_watch_kind (experimental, since 1.1): what cdm.watch reports."""
    CDM_WATCH_ARRIVED = 1
    CDM_WATCH_LEFT = 2


class WatchFlag(enum.IntFlag):
    """cdm_watch_flag (experimental, since 1.1)."""
    CDM_WATCH_ENUMERATE = 1 << 0


class EffectStage(enum.IntEnum):
    """cdm_effect_stage (experimental, since 1.2): where a user effect acts."""
    CDM_EFFECT_STAGE_READING = 0
    CDM_EFFECT_STAGE_PATH = 1


_ENUMS = (Error, PoseFlag, Button, EventKind, LogLevel, WatchKind, WatchFlag, EffectStage)

# The header's names, flat, as module attributes (cdm.CDM_ERR_NO_DEVICE, ...).
globals().update({str(m.name): int(m) for e in _ENUMS for m in e})

__all__ = ["Error", "PoseFlag", "Button", "EventKind", "LogLevel", "WatchKind", "WatchFlag", "EffectStage",
           "CDM_ERROR_COUNT", "CDM_VERSION_MAJOR",
           "CDM_VERSION_MINOR", "CDM_VERSION_PATCH", "CDM_VERSION_NUMBER"] + [str(m.name) for e in _ENUMS for m in e]
