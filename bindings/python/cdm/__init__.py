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
from .calibration import Calibration
from .constants import *  # noqa: F401,F403 - the header's constants
from .constants import Button, Error, PoseFlag
from .device import Device, DeviceInfo, Pose, Raw, Sample, Stats, enumerate_devices, open  # noqa: A004
from .diagnosis import Diagnosis, diagnose, fit, load_diagnosis
from .effects import EffectGeometry, effect_names, load_plugin, register_effect, unregister_effect
from . import frames
from . import log
from .watch import Watcher, watch
from .errors import (CdmError, CdmFileNotFoundError, CdmIOError, CdmMemoryError, CdmTimeoutError,
                     DisconnectedError, InvalidArgumentError, LibraryNotFoundError, NoDeviceError, ParseError)
from . import constants as _constants

__all__ = ["open", "enumerate", "enumerate_devices", "Device", "DeviceInfo", "Pose", "Raw", "Sample", "Stats",
           "Calibration", "Diagnosis", "diagnose", "fit", "load_diagnosis",
           "effect_names", "load_plugin", "register_effect", "unregister_effect", "EffectGeometry",
           "CdmError", "InvalidArgumentError", "ParseError", "NoDeviceError", "CdmIOError", "CdmFileNotFoundError",
           "CdmTimeoutError", "DisconnectedError", "CdmMemoryError", "LibraryNotFoundError",
           "Watcher", "watch", "frames", "log", "version", "version_number", "library_path"] + list(_constants.__all__)



def __getattr__(name: str) -> str:
    # __version__ is the loaded library's (the version lives in one place,
    # CMakeLists.txt); read lazily so that `import cdm` works without libcdm,
    # and from the installed package's metadata when libcdm cannot be loaded.
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
    return _native.lib().cdm_version().decode("ascii")


def version_number() -> int:
    """CDM_VERSION_NUMBER of the libcdm actually loaded."""
    return _native.lib().cdm_version_number()


def library_path() -> str:
    """Path (or name) of the libcdm actually loaded."""
    return _native.lib().path
