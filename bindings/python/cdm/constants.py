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
    """cdm_error: return codes (pinned values).

    Members drop the C prefix (Error.OK is CDM_OK); the C names stay as aliases."""
    OK = 0
    INVALID_ARG = -1
    NO_DEVICE = -2
    IO = -3
    TIMEOUT = -4
    DISCONNECTED = -5
    STALE = -6
    NO_DATA = -7
    PROTOCOL = -8
    UNSUPPORTED = -9
    NO_MEM = -10
    PARSE = -11
    NUMERIC = -12
    END_OF_STREAM = -13
    CRC = -14
    INTERNAL = -15
    CLOSED = -16  # since 1.2: a wait ended by close()
    CDM_OK = OK
    CDM_ERR_INVALID_ARG = INVALID_ARG
    CDM_ERR_NO_DEVICE = NO_DEVICE
    CDM_ERR_IO = IO
    CDM_ERR_TIMEOUT = TIMEOUT
    CDM_ERR_DISCONNECTED = DISCONNECTED
    CDM_ERR_STALE = STALE
    CDM_ERR_NO_DATA = NO_DATA
    CDM_ERR_PROTOCOL = PROTOCOL
    CDM_ERR_UNSUPPORTED = UNSUPPORTED
    CDM_ERR_NO_MEM = NO_MEM
    CDM_ERR_PARSE = PARSE
    CDM_ERR_NUMERIC = NUMERIC
    CDM_ERR_END_OF_STREAM = END_OF_STREAM
    CDM_ERR_CRC = CRC
    CDM_ERR_INTERNAL = INTERNAL
    CDM_ERR_CLOSED = CLOSED


CDM_ERROR_COUNT = 17


class PoseFlag(enum.IntFlag):
    """cdm_pose_flag: bits of Pose.flags.

    Members drop the C prefix (PoseFlag.STALE is CDM_POSE_STALE); the C names stay as aliases."""
    STALE = 1 << 0
    DISCONNECTED = 1 << 1
    COMPENSATED = 1 << 2
    OUT_OF_WORKSPACE = 1 << 3
    END_OF_STREAM = 1 << 4
    NO_POSITION = 1 << 5  # since 1.1
    CDM_POSE_STALE = STALE
    CDM_POSE_DISCONNECTED = DISCONNECTED
    CDM_POSE_COMPENSATED = COMPENSATED
    CDM_POSE_OUT_OF_WORKSPACE = OUT_OF_WORKSPACE
    CDM_POSE_END_OF_STREAM = END_OF_STREAM
    CDM_POSE_NO_POSITION = NO_POSITION


class Button(enum.IntFlag):
    """cdm_button: bits of Pose.buttons.

    Members drop the C prefix (Button.CLUTCH is CDM_BUTTON_CLUTCH); the C names stay as aliases."""
    CLUTCH = 1 << 0
    AUX = 1 << 1
    MARK = 1 << 2
    CDM_BUTTON_CLUTCH = CLUTCH
    CDM_BUTTON_AUX = AUX
    CDM_BUTTON_MARK = MARK


class EventKind(enum.IntEnum):
    """cdm_event_kind (since 1.1): what on_event reports.

    Members drop the C prefix (EventKind.DISCONNECTED is CDM_EVENT_DISCONNECTED); the C names stay as aliases."""
    DISCONNECTED = 1
    RECONNECTED = 2
    STALE = 3
    FRESH = 4
    END_OF_STREAM = 5
    CDM_EVENT_DISCONNECTED = DISCONNECTED
    CDM_EVENT_RECONNECTED = RECONNECTED
    CDM_EVENT_STALE = STALE
    CDM_EVENT_FRESH = FRESH
    CDM_EVENT_END_OF_STREAM = END_OF_STREAM


class RejectedKind(enum.IntEnum):
    """cdm_rejected_kind (since 1.2): why the reader discarded a report.

    Members drop the C prefix (RejectedKind.MALFORMED is CDM_REJECTED_MALFORMED); the C names stay as aliases."""
    MALFORMED = 1
    OUT_OF_ORDER = 2
    CDM_REJECTED_MALFORMED = MALFORMED
    CDM_REJECTED_OUT_OF_ORDER = OUT_OF_ORDER


class LogLevel(enum.IntEnum):
    """cdm_log_level (since 1.1): levels of cdm_set_log_fn's messages.

    Members drop the C prefix (LogLevel.DEBUG is CDM_LOG_DEBUG); the C names stay as aliases."""
    DEBUG = 0
    INFO = 1
    WARNING = 2
    ERROR = 3
    CDM_LOG_DEBUG = DEBUG
    CDM_LOG_INFO = INFO
    CDM_LOG_WARNING = WARNING
    CDM_LOG_ERROR = ERROR


class WatchKind(enum.IntEnum):
    """cdm_watch_kind (experimental, since 1.1): what cdm.watch reports.

    Members drop the C prefix (WatchKind.ARRIVED is CDM_WATCH_ARRIVED); the C names stay as aliases."""
    ARRIVED = 1
    LEFT = 2
    CDM_WATCH_ARRIVED = ARRIVED
    CDM_WATCH_LEFT = LEFT


class WatchFlag(enum.IntFlag):
    """cdm_watch_flag (experimental, since 1.1).

    Members drop the C prefix (WatchFlag.ENUMERATE is CDM_WATCH_ENUMERATE); the C names stay as aliases."""
    ENUMERATE = 1 << 0
    CDM_WATCH_ENUMERATE = ENUMERATE


class EffectStage(enum.IntEnum):
    """cdm_effect_stage (experimental, since 1.2): where a user effect acts.

    Members drop the C prefix (EffectStage.READING is CDM_EFFECT_STAGE_READING); the C names stay as aliases."""
    READING = 0
    PATH = 1
    CDM_EFFECT_STAGE_READING = READING
    CDM_EFFECT_STAGE_PATH = PATH


_ENUMS = (Error, PoseFlag, Button, EventKind, RejectedKind, LogLevel, WatchKind, WatchFlag, EffectStage)

# The header's names, flat, as module attributes (cdm.CDM_ERR_NO_DEVICE, ...): plain ints.
CDM_OK = int(Error.OK)
CDM_ERR_INVALID_ARG = int(Error.INVALID_ARG)
CDM_ERR_NO_DEVICE = int(Error.NO_DEVICE)
CDM_ERR_IO = int(Error.IO)
CDM_ERR_TIMEOUT = int(Error.TIMEOUT)
CDM_ERR_DISCONNECTED = int(Error.DISCONNECTED)
CDM_ERR_STALE = int(Error.STALE)
CDM_ERR_NO_DATA = int(Error.NO_DATA)
CDM_ERR_PROTOCOL = int(Error.PROTOCOL)
CDM_ERR_UNSUPPORTED = int(Error.UNSUPPORTED)
CDM_ERR_NO_MEM = int(Error.NO_MEM)
CDM_ERR_PARSE = int(Error.PARSE)
CDM_ERR_NUMERIC = int(Error.NUMERIC)
CDM_ERR_END_OF_STREAM = int(Error.END_OF_STREAM)
CDM_ERR_CRC = int(Error.CRC)
CDM_ERR_INTERNAL = int(Error.INTERNAL)
CDM_ERR_CLOSED = int(Error.CLOSED)
CDM_POSE_STALE = int(PoseFlag.STALE)
CDM_POSE_DISCONNECTED = int(PoseFlag.DISCONNECTED)
CDM_POSE_COMPENSATED = int(PoseFlag.COMPENSATED)
CDM_POSE_OUT_OF_WORKSPACE = int(PoseFlag.OUT_OF_WORKSPACE)
CDM_POSE_END_OF_STREAM = int(PoseFlag.END_OF_STREAM)
CDM_POSE_NO_POSITION = int(PoseFlag.NO_POSITION)
CDM_BUTTON_CLUTCH = int(Button.CLUTCH)
CDM_BUTTON_AUX = int(Button.AUX)
CDM_BUTTON_MARK = int(Button.MARK)
CDM_EVENT_DISCONNECTED = int(EventKind.DISCONNECTED)
CDM_EVENT_RECONNECTED = int(EventKind.RECONNECTED)
CDM_EVENT_STALE = int(EventKind.STALE)
CDM_EVENT_FRESH = int(EventKind.FRESH)
CDM_EVENT_END_OF_STREAM = int(EventKind.END_OF_STREAM)
CDM_REJECTED_MALFORMED = int(RejectedKind.MALFORMED)
CDM_REJECTED_OUT_OF_ORDER = int(RejectedKind.OUT_OF_ORDER)
CDM_LOG_DEBUG = int(LogLevel.DEBUG)
CDM_LOG_INFO = int(LogLevel.INFO)
CDM_LOG_WARNING = int(LogLevel.WARNING)
CDM_LOG_ERROR = int(LogLevel.ERROR)
CDM_WATCH_ARRIVED = int(WatchKind.ARRIVED)
CDM_WATCH_LEFT = int(WatchKind.LEFT)
CDM_WATCH_ENUMERATE = int(WatchFlag.ENUMERATE)
CDM_EFFECT_STAGE_READING = int(EffectStage.READING)
CDM_EFFECT_STAGE_PATH = int(EffectStage.PATH)

__all__ = ["Error", "PoseFlag", "Button", "EventKind", "RejectedKind", "LogLevel", "WatchKind", "WatchFlag", "EffectStage",
           "CDM_ERROR_COUNT", "CDM_VERSION_MAJOR", "CDM_VERSION_MINOR", "CDM_VERSION_PATCH", "CDM_VERSION_NUMBER",
           "CDM_OK", "CDM_ERR_INVALID_ARG", "CDM_ERR_NO_DEVICE", "CDM_ERR_IO", "CDM_ERR_TIMEOUT",
           "CDM_ERR_DISCONNECTED", "CDM_ERR_STALE", "CDM_ERR_NO_DATA", "CDM_ERR_PROTOCOL",
           "CDM_ERR_UNSUPPORTED", "CDM_ERR_NO_MEM", "CDM_ERR_PARSE", "CDM_ERR_NUMERIC",
           "CDM_ERR_END_OF_STREAM", "CDM_ERR_CRC", "CDM_ERR_INTERNAL", "CDM_ERR_CLOSED", "CDM_POSE_STALE",
           "CDM_POSE_DISCONNECTED", "CDM_POSE_COMPENSATED", "CDM_POSE_OUT_OF_WORKSPACE",
           "CDM_POSE_END_OF_STREAM", "CDM_POSE_NO_POSITION", "CDM_BUTTON_CLUTCH", "CDM_BUTTON_AUX",
           "CDM_BUTTON_MARK", "CDM_EVENT_DISCONNECTED", "CDM_EVENT_RECONNECTED", "CDM_EVENT_STALE",
           "CDM_EVENT_FRESH", "CDM_EVENT_END_OF_STREAM", "CDM_REJECTED_MALFORMED", "CDM_REJECTED_OUT_OF_ORDER",
           "CDM_LOG_DEBUG", "CDM_LOG_INFO", "CDM_LOG_WARNING",
           "CDM_LOG_ERROR", "CDM_WATCH_ARRIVED", "CDM_WATCH_LEFT", "CDM_WATCH_ENUMERATE",
           "CDM_EFFECT_STAGE_READING", "CDM_EFFECT_STAGE_PATH"]
