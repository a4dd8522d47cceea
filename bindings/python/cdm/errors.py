"""The binding's exceptions.

Every failing libcdm call raises a CdmError. Its subclasses also derive from
the built-in exception a Python user already catches, so code that does not
know cdm still handles the failure sensibly:

    ===========================  ==========================================
    CDM_ERR_INVALID_ARG          InvalidArgumentError (ValueError)
    CDM_ERR_PARSE                ParseError (ValueError)
    CDM_ERR_NO_DEVICE            NoDeviceError (FileNotFoundError)
    CDM_ERR_IO                   CdmIOError (OSError); FileNotFoundError too
                                 when the file does not exist
    CDM_ERR_TIMEOUT              CdmTimeoutError (TimeoutError)
    CDM_ERR_DISCONNECTED         DisconnectedError (ConnectionError)
    CDM_ERR_NO_MEM               CdmMemoryError (MemoryError)
    any other code               CdmError
    ===========================  ==========================================

`CdmError(code, message)` builds the subclass that fits the code.
"""
import errno as _errno
from typing import Dict, Iterable, Optional, Tuple, Type

from .constants import Error

__all__ = ["CdmError", "InvalidArgumentError", "ParseError", "NoDeviceError", "CdmIOError",
           "CdmFileNotFoundError", "CdmTimeoutError", "DisconnectedError", "CdmMemoryError",
           "LibraryNotFoundError"]


class CdmError(Exception):
    """A libcdm call failed.

    code     the cdm_error value (negative int; compare with cdm.CDM_ERR_*)
    message  cdm_strerror(code), then the library's detail text (what was
             wrong and where: file:line:column, URI option, ...) when it gave one
    detail   the detail text alone ("" when none)
    function the C function that failed (e.g. "cdm_open"), or None
    """

    code: int
    message: str
    detail: str
    function: Optional[str]

    def __new__(cls, code: int, message: str = "", detail: str = "", function: Optional[str] = None) -> "CdmError":
        if cls is CdmError:
            cls = _subclass_for(int(code), detail or message)
        return super().__new__(cls)

    def __init__(self, code: int, message: str = "", detail: str = "", function: Optional[str] = None) -> None:
        Exception.__init__(self, int(code), message)
        self.code = int(code)
        self.message = message
        self.detail = detail
        self.function = function

    @property
    def name(self) -> str:
        """"CDM_ERR_NO_DEVICE" and so on; "unknown error <code>" for codes this binding does not know."""
        return _C_NAMES.get(self.code, "unknown error %d" % self.code)

    def __str__(self) -> str:
        where = "%s: " % self.function if self.function else ""
        return "%s%s (%s)" % (where, self.message, self.name)

    def __repr__(self) -> str:
        return "%s(%d, %r)" % (type(self).__name__, self.code, self.message)

    def __reduce__(self) -> Tuple[Type["CdmError"], Tuple[int, str, str, Optional[str]]]:
        """Picklable across processes (multiprocessing, concurrent.futures)."""
        return (CdmError, (self.code, self.message, self.detail, self.function))


class InvalidArgumentError(CdmError, ValueError):
    """CDM_ERR_INVALID_ARG: a bad argument, option or URI."""


class ParseError(CdmError, ValueError):
    """CDM_ERR_PARSE: a malformed file (JSON, CSV, recording); the detail names file:line:column."""


class NoDeviceError(CdmError, FileNotFoundError):
    """CDM_ERR_NO_DEVICE: no such device, or an unknown URI scheme."""


class CdmIOError(CdmError, OSError):
    """CDM_ERR_IO: the transport or a file failed; the detail carries the system's reason."""


class CdmFileNotFoundError(CdmIOError, FileNotFoundError):
    """CDM_ERR_IO because a file does not exist."""


class CdmTimeoutError(CdmError, TimeoutError):
    """CDM_ERR_TIMEOUT: nothing arrived in time."""


class DisconnectedError(CdmError, ConnectionError):
    """CDM_ERR_DISCONNECTED: the device is gone (the handle keeps trying to reconnect)."""


class CdmMemoryError(CdmError, MemoryError):
    """CDM_ERR_NO_MEM."""


# The C names (CDM_ERR_TIMEOUT) the messages show: the enum's members drop the prefix.
_C_NAMES: Dict[int, str] = {int(v): k for k, v in Error.__members__.items() if k.startswith("CDM_")}

_BY_CODE: Dict[int, Type[CdmError]] = {
    int(Error.CDM_ERR_INVALID_ARG): InvalidArgumentError,
    int(Error.CDM_ERR_PARSE): ParseError,
    int(Error.CDM_ERR_NO_DEVICE): NoDeviceError,
    int(Error.CDM_ERR_IO): CdmIOError,
    int(Error.CDM_ERR_TIMEOUT): CdmTimeoutError,
    int(Error.CDM_ERR_DISCONNECTED): DisconnectedError,
    int(Error.CDM_ERR_NO_MEM): CdmMemoryError,
}


def _subclass_for(code: int, text: str) -> Type[CdmError]:
    cls = _BY_CODE.get(code, CdmError)
    if cls is CdmIOError and _errno_text(_errno.ENOENT) in text:
        return CdmFileNotFoundError
    return cls


def _errno_text(e: int) -> str:
    import os
    return os.strerror(e)


class LibraryNotFoundError(OSError):
    """libcdm could not be loaded; .tried lists (path, reason) for every candidate, in order."""

    def __init__(self, tried: Iterable[Tuple[str, str]]) -> None:
        self.tried = list(tried)
        lines = ["libcdm could not be loaded; tried, in order:"]
        lines += ["  %s: %s" % (path, reason) for path, reason in self.tried]
        lines.append("Set CDM_LIBRARY to the library file (e.g. build/src/libcdm.so.1), or CDM_BUILD_DIR "
                     "to a build tree, or install libcdm (cmake --install).")
        super().__init__("\n".join(lines))
