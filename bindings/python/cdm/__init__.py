"""cdm: Python binding of libcdm, the cable-driven haptic master driver.

    import cdm
    with cdm.open("sim:") as dev:
        pose = dev.wait_pose(1.0)
        print(pose.position, pose.orientation, pose.grip)

Pure ctypes: libcdm is found through $CDM_LIBRARY, then beside this package,
then $CDM_BUILD_DIR/src, then the system (see docs/bindings.md). It is loaded
on first use, so `import cdm` works without it. Every failing call raises
cdm.CdmError(code, message), as the subclass that also derives from the
built-in a Python user catches (TimeoutError, FileNotFoundError,
ConnectionError, ValueError...; see cdm.errors).
"""
from . import _native
from . import constants as constants
from . import frames as frames
from . import log as log
from . import records as records
from .calibration import Calibration
from .constants import *  # noqa: F401,F403 - the header's constants
from .constants import Button, EffectStage, Error, EventKind, LogLevel, PoseFlag, RejectedKind, WatchFlag, WatchKind
from .device import Device, enumerate_devices, open  # noqa: A004
from .diagnosis import Diagnosis, accuracy_map, check, diagnose, fit, load_diagnosis, plan
from .effects import EffectGeometry, effect_names, load_plugin, register_effect, unregister_effect
from .errors import (CdmError, CdmFileNotFoundError, CdmIOError, CdmMemoryError, CdmTimeoutError,
                     DisconnectedError, InvalidArgumentError, LibraryNotFoundError, NoDeviceError, ParseError)
from .records import DeviceInfo, Pose, Raw, Sample, Stats
from .watch import Watcher, watch

__all__ = ["open", "enumerate", "enumerate_devices", "Device", "DeviceInfo", "Pose", "Raw", "Sample", "Stats",
           "Calibration", "Diagnosis", "accuracy_map", "check", "diagnose", "fit", "load_diagnosis", "plan",
           "effect_names", "load_plugin", "register_effect", "unregister_effect", "EffectGeometry",
           "CdmError", "InvalidArgumentError", "ParseError", "NoDeviceError", "CdmIOError", "CdmFileNotFoundError",
           "CdmTimeoutError", "DisconnectedError", "CdmMemoryError", "LibraryNotFoundError",
           "Watcher", "watch", "frames", "log", "records", "version", "version_number", "library_path"]
__all__ += constants.__all__


def __getattr__(name: str) -> str:
    """cdm.__version__: the loaded library's version (read lazily, so that
    `import cdm` works without libcdm), else the installed package's."""
    if name == "__version__":
        try:
            return version()
        except LibraryNotFoundError:
            from importlib.metadata import PackageNotFoundError
            from importlib.metadata import version as _dist_version

            try:
                return _dist_version("cdm-haptics")
            except PackageNotFoundError:
                return "unknown"
    raise AttributeError("module 'cdm' has no attribute %r" % name)

# cdm.enumerate() mirrors cdm_enumerate; enumerate_devices is the same without
# shadowing the builtin in `from cdm import *`.
enumerate = enumerate_devices  # noqa: A001


def version() -> str:
    """Version text of the libcdm actually loaded ("1.2.0")."""
    return _native.text(_native.lib().cdm_version())


def version_number() -> int:
    """CDM_VERSION_NUMBER of the libcdm actually loaded."""
    return _native.lib().cdm_version_number()


def library_path() -> str:
    """Path (or name) of the libcdm actually loaded."""
    return _native.lib().path
