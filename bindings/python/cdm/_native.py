"""ctypes mirror of include/cdm/cdm.h: structures, prototypes, library loading.

Every function of the header, the CDM_EXPERIMENTAL ones included, has its
argtypes and restype here (tests/python/test_prototypes.py checks the list
against the header). Nothing else in the package touches ctypes prototypes.
"""
import ctypes
import ctypes.util
import os
import sys
import threading
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Type, TypeVar, Union

from .constants import CDM_VERSION_MAJOR, Error
from .errors import CdmError, LibraryNotFoundError

c_double_p = ctypes.POINTER(ctypes.c_double)


class _Sized(ctypes.Structure):
    """A public struct: struct_size is set to sizeof() on construction."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.struct_size = ctypes.sizeof(self)


class cdm_pose(_Sized):
    _fields_ = [
        ("struct_size", ctypes.c_uint32),
        ("flags", ctypes.c_uint32),
        ("position", ctypes.c_double * 3),
        ("orientation", ctypes.c_double * 4),
        ("grip", ctypes.c_double),
        ("buttons", ctypes.c_uint32),
        ("sequence", ctypes.c_uint32),
        ("device_time_us", ctypes.c_uint64),
        ("host_time_ns", ctypes.c_uint64),
        ("dropped", ctypes.c_uint32),
        ("reserved0", ctypes.c_uint32),
        ("host_sequence", ctypes.c_uint64),  # since 1.1
        ("velocity", ctypes.c_double * 3),  # since 1.1
    ]


class cdm_raw(_Sized):
    _fields_ = [
        ("struct_size", ctypes.c_uint32),
        ("status", ctypes.c_uint32),
        ("pot_adc", ctypes.c_uint16 * 4),
        ("hall_adc", ctypes.c_uint16),
        ("buttons", ctypes.c_uint16),
        ("quat_q14", ctypes.c_int16 * 4),
        ("sequence", ctypes.c_uint32),
        ("lengths_mm", ctypes.c_double * 4),
        ("device_time_us", ctypes.c_uint64),
        ("host_time_ns", ctypes.c_uint64),
    ]


class cdm_device_info(_Sized):
    _fields_ = [
        ("struct_size", ctypes.c_uint32),
        ("vendor_id", ctypes.c_uint16),
        ("product_id", ctypes.c_uint16),
        ("uri", ctypes.c_char * 256),
        ("serial", ctypes.c_char * 32),
        ("firmware", ctypes.c_char * 16),
        ("transport", ctypes.c_char * 16),
        ("protocol_version", ctypes.c_uint32),
        ("adc_bits", ctypes.c_uint32),
        ("pot_scale_mm", ctypes.c_double * 4),
        ("pot_offset_mm", ctypes.c_double * 4),
        ("a_mm", ctypes.c_double),
        ("b_mm", ctypes.c_double),
        ("m_mm", ctypes.c_double),
        ("report_rate_hz", ctypes.c_double),
        ("hall_closed", ctypes.c_double),
        ("hall_open", ctypes.c_double),
        ("grip_open_rad", ctypes.c_double),
    ]


class cdm_stats(_Sized):
    _fields_ = [
        ("struct_size", ctypes.c_uint32),
        ("reserved0", ctypes.c_uint32),
        ("reports", ctypes.c_uint64),
        ("malformed", ctypes.c_uint64),
        ("dropped", ctypes.c_uint64),
        ("out_of_workspace", ctypes.c_uint64),
        ("reconnects", ctypes.c_uint64),
        ("sequence_jumps", ctypes.c_uint64),  # since 1.1
        ("out_of_order", ctypes.c_uint64),  # since 1.1
        ("replay_truncated_bytes", ctypes.c_uint64),  # since 1.1
        ("restarts", ctypes.c_uint64),  # since 1.2
    ]


class cdm_sample(_Sized):
    _fields_ = [
        ("struct_size", ctypes.c_uint32),
        ("report_len", ctypes.c_uint32),
        ("report", ctypes.POINTER(ctypes.c_uint8)),
        ("raw", ctypes.POINTER(cdm_raw)),
        ("pose", ctypes.POINTER(cdm_pose)),
        ("source_time_ns", ctypes.c_uint64),  # since 1.1
    ]


cdm_sample_fn = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.POINTER(cdm_sample))


class cdm_event(_Sized):
    _fields_ = [
        ("struct_size", ctypes.c_uint32),
        ("kind", ctypes.c_uint32),
        ("host_time_ns", ctypes.c_uint64),
        ("text", ctypes.c_char_p),
    ]


cdm_event_fn = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.POINTER(cdm_event))
cdm_log_fn = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_int, ctypes.c_char_p)


class cdm_rejected(_Sized):
    _fields_ = [
        ("struct_size", ctypes.c_uint32),
        ("kind", ctypes.c_uint32),
        ("report", ctypes.POINTER(ctypes.c_uint8)),
        ("report_len", ctypes.c_uint32),
        ("reserved0", ctypes.c_uint32),
        ("source_time_ns", ctypes.c_uint64),
        ("reason", ctypes.c_char_p),
    ]


cdm_rejected_fn = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.POINTER(cdm_rejected))


class cdm_open_options(_Sized):
    _fields_ = [
        ("struct_size", ctypes.c_uint32),
        ("stale_timeout_us", ctypes.c_uint32),
        ("on_sample", cdm_sample_fn),
        ("user", ctypes.c_void_p),
        ("on_event", cdm_event_fn),  # since 1.1
        ("on_rejected", cdm_rejected_fn),  # since 1.2: not set by this binding
    ]


cdm_effect_apply_fn = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, c_double_p, c_double_p, c_double_p)
cdm_effect_apply_batch_fn = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, c_double_p, ctypes.c_size_t, c_double_p,
                                             c_double_p)


class cdm_effect_context(_Sized):  # CDM_EXPERIMENTAL, since 1.2
    _fields_ = [
        ("struct_size", ctypes.c_uint32),
        ("stage", ctypes.c_uint32),
        ("n", ctypes.c_size_t),
        ("positions_mm", c_double_p),
        ("t_s", c_double_p),
        ("anchors_mm", c_double_p),
        ("holders_mm", c_double_p),
        ("unit", c_double_p),
        ("chord_mm", c_double_p),
    ]


cdm_effect_apply_geom_fn = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, c_double_p, ctypes.c_size_t,
                                            ctypes.POINTER(cdm_effect_context), c_double_p)


class cdm_effect_def(_Sized):
    _fields_ = [
        ("struct_size", ctypes.c_uint32),
        ("n_params", ctypes.c_uint32),
        ("name", ctypes.c_char_p),
        ("doc", ctypes.c_char_p),
        ("param_names", ctypes.POINTER(ctypes.c_char_p)),
        ("param_scale", c_double_p),
        ("lower", c_double_p),
        ("upper", c_double_p),
        ("apply", cdm_effect_apply_fn),
        ("user", ctypes.c_void_p),
        ("initial", c_double_p),  # since 1.1
        ("apply_batch", cdm_effect_apply_batch_fn),  # since 1.1
        ("param_units", ctypes.POINTER(ctypes.c_char_p)),  # since 1.2
        ("apply_geom", cdm_effect_apply_geom_fn),  # since 1.2
        ("origin", ctypes.c_char_p),  # since 1.2
        ("stage", ctypes.c_uint32),  # since 1.2
    ]


cdm_progress_fn = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_char_p, ctypes.c_double)

class cdm_watch_event(_Sized):  # CDM_EXPERIMENTAL, since 1.1
    _fields_ = [
        ("struct_size", ctypes.c_uint32),
        ("kind", ctypes.c_uint32),
        ("host_time_ns", ctypes.c_uint64),
        ("info", ctypes.POINTER(cdm_device_info)),
    ]


cdm_watch_fn = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.POINTER(cdm_watch_event))

STRUCTS: Dict[str, Type[_Sized]] = {cls.__name__: cls for cls in
           (cdm_pose, cdm_raw, cdm_device_info, cdm_stats, cdm_sample, cdm_rejected, cdm_open_options,
            cdm_effect_context,
            cdm_effect_def, cdm_event, cdm_watch_event)}

# Opaque handles travel as void pointers.
_handle = ctypes.c_void_p
_handle_p = ctypes.POINTER(ctypes.c_void_p)
_int, _size, _str = ctypes.c_int, ctypes.c_size_t, ctypes.c_char_p

# name: (restype, argtypes), in the header's order.
PROTOTYPES: Dict[str, Tuple[Any, List[Any]]] = {
    "cdm_version": (_str, []),
    "cdm_version_number": (_int, []),
    "cdm_strerror": (_str, [_int]),
    "cdm_thread_error": (_str, []),
    "cdm_enumerate": (_int, [_handle_p]),
    "cdm_device_list_count": (_size, [_handle]),
    "cdm_device_list_get": (_int, [_handle, _size, ctypes.POINTER(cdm_device_info)]),
    "cdm_device_list_free": (None, [_handle]),
    "cdm_open": (_int, [_str, _handle_p]),
    "cdm_open_ex": (_int, [_str, ctypes.POINTER(cdm_open_options), _handle_p]),
    "cdm_close": (None, [_handle]),
    "cdm_shutdown": (_int, [_handle]),  # since 1.2
    "cdm_get_pose": (_int, [_handle, ctypes.POINTER(cdm_pose)]),
    "cdm_wait_pose": (_int, [_handle, _int, ctypes.POINTER(cdm_pose)]),
    "cdm_wait_pose_after": (_int, [_handle, ctypes.c_uint64, _int, ctypes.POINTER(cdm_pose)]),
    "cdm_set_log_fn": (None, [cdm_log_fn, ctypes.c_void_p]),
    "cdm_get_raw": (_int, [_handle, ctypes.POINTER(cdm_raw)]),
    "cdm_get_info": (_int, [_handle, ctypes.POINTER(cdm_device_info)]),
    "cdm_set_stale_timeout": (_int, [_handle, ctypes.c_uint32]),
    "cdm_get_stats": (_int, [_handle, ctypes.POINTER(cdm_stats)]),
    "cdm_device_error": (_int, [_handle, ctypes.c_char_p, _size]),
    "cdm_calibration_load": (_int, [_str, _handle_p]),
    "cdm_calibration_parse": (_int, [_str, _size, _handle_p]),
    "cdm_calibration_free": (None, [_handle]),
    "cdm_calibration_position": (_int, [_handle, c_double_p, c_double_p]),
    "cdm_calibration_lengths": (_int, [_handle, c_double_p, c_double_p]),
    "cdm_calibration_position_covariance": (_int, [_handle, c_double_p, c_double_p]),
    "cdm_calibration_effect_count": (_size, [_handle]),
    "cdm_calibration_effect_name": (_str, [_handle, _size]),
    "cdm_set_calibration": (_int, [_handle, _handle]),
    "cdm_device_calibration_read": (_int, [_handle, ctypes.c_char_p, _size, ctypes.POINTER(ctypes.c_size_t)]),
    "cdm_device_calibration_write": (_int, [_handle, ctypes.c_char_p, _size]),
    # CDM_EXPERIMENTAL
    "cdm_effect_register": (_int, [ctypes.POINTER(cdm_effect_def)]),
    "cdm_effect_unregister": (_int, [_str]),
    "cdm_effect_load_plugin": (_int, [_str]),
    "cdm_effect_count": (_size, []),
    "cdm_effect_name": (_str, [_size]),
    "cdm_effect_fingerprint": (_int, [_size, ctypes.c_char_p, _size, ctypes.POINTER(ctypes.c_char_p)]),
    # result_json is a char** the library allocates: received as a void pointer
    # so that ctypes does not copy it away before cdm_free_string gets it.
    "cdm_diagnose": (_int, [_str, _str, _str, cdm_progress_fn, ctypes.c_void_p, _handle_p]),
    "cdm_fit": (_int, [_str, _str, _str, cdm_progress_fn, ctypes.c_void_p, _handle_p]),
    "cdm_check": (_int, [_str, _str, _str, cdm_progress_fn, ctypes.c_void_p, _handle_p]),
    "cdm_plan": (_int, [_str, cdm_progress_fn, ctypes.c_void_p, _handle_p]),
    "cdm_free_string": (None, [ctypes.c_void_p]),
    # since 1.1: the one dataset writer
    "cdm_dataset_writer_open": (_int, [_str, ctypes.POINTER(ctypes.c_char_p), ctypes.c_size_t, _handle_p]),
    "cdm_dataset_writer_add": (_int, [_handle, _int, c_double_p, c_double_p]),
    "cdm_dataset_writer_add_at": (_int, [_handle, _int, c_double_p, c_double_p, ctypes.c_double]),
    "cdm_dataset_writer_commit": (_int, [_handle]),
    "cdm_dataset_writer_free": (None, [_handle]),
    # CDM_EXPERIMENTAL, tools (the `cdm` command's needs)
    "cdm_device_info_report": (_int, [_handle, ctypes.POINTER(ctypes.c_uint8), _size, ctypes.POINTER(ctypes.c_size_t)]),
    "cdm_sim_truth": (_int, [_handle, ctypes.c_uint32, c_double_p]),
    "cdm_recorder_open": (_int, [_str, ctypes.POINTER(ctypes.c_uint8), _size, _handle_p]),
    "cdm_recorder_write": (_int, [_handle, ctypes.c_uint64, ctypes.POINTER(ctypes.c_uint8), _size]),
    "cdm_recorder_close": (_int, [_handle]),
    "cdm_recorder_open_ex": (_int, [_str, _str, ctypes.POINTER(ctypes.c_uint8), _size, _handle_p]),
    "cdm_recorder_write_sample": (_int, [_handle, ctypes.POINTER(cdm_sample)]),
    "cdm_recorder_write_rejected": (_int, [_handle, ctypes.POINTER(cdm_rejected)]),
    "cdm_jig_plan_create": (_int, [_str, _int, ctypes.c_double, c_double_p, _size, _int, _handle_p]),
    "cdm_jig_plan_count": (_size, [_handle]),
    "cdm_jig_plan_samples": (_int, [_handle]),
    "cdm_jig_plan_get": (_int, [_handle, _size, ctypes.POINTER(ctypes.c_int), c_double_p]),
    "cdm_jig_plan_use_file": (_int, [_handle, ctypes.c_char_p]),
    "cdm_jig_plan_samples_at": (_int, [_handle, _size]),
    "cdm_jig_plan_plate": (_int, [_handle, ctypes.POINTER(ctypes.c_int), c_double_p, c_double_p, _size,
                                  ctypes.POINTER(ctypes.c_size_t)]),
    "cdm_plan_file_read": (_int, [ctypes.c_char_p, ctypes.POINTER(ctypes.c_void_p)]),
    "cdm_jig_plan_free": (None, [_handle]),
    "cdm_effect_doc": (_str, [_size]),
    "cdm_effect_param_count": (_size, [_size]),
    "cdm_effect_param": (_int, [_size, _size, ctypes.POINTER(ctypes.c_char_p), ctypes.POINTER(ctypes.c_char_p),
                                c_double_p, c_double_p, c_double_p]),
    "cdm_nominal_device_json": (_int, [_handle_p]),
    "cdm_device_file_read": (_int, [_str, _handle_p]),
    "cdm_simulate_jig_defaults": (_int, [_handle_p]),
    "cdm_simulate_jig_dataset": (_int, [_str, _str]),
    "cdm_write_file_atomic": (_int, [_str, ctypes.c_void_p, _size, ctypes.POINTER(ctypes.c_char_p), _size]),
    # CDM_EXPERIMENTAL, hot-plug
    "cdm_watch": (_int, [ctypes.c_uint32, cdm_watch_fn, ctypes.c_void_p, _handle_p]),
    "cdm_watch_free": (None, [_handle]),
}


def _library_names() -> List[str]:
    if sys.platform == "darwin":
        return ["libcdm.1.dylib", "libcdm.dylib"]
    if sys.platform == "win32":
        return ["cdm.dll", "libcdm.dll"]
    return ["libcdm.so.1", "libcdm.so"]


def candidates(environ: Optional[Mapping[str, str]] = None) -> List[Tuple[str, str]]:
    """Where the library is looked for, in order: [(path or name, origin), ...]."""
    env = os.environ if environ is None else environ
    out: List[Tuple[str, str]] = []
    if env.get("CDM_LIBRARY"):
        out.append((env["CDM_LIBRARY"], "$CDM_LIBRARY"))
    here = os.path.dirname(os.path.abspath(__file__))
    out += [(os.path.join(here, n), "beside the package") for n in _library_names()]
    if env.get("CDM_BUILD_DIR"):
        out += [(os.path.join(env["CDM_BUILD_DIR"], "src", n), "$CDM_BUILD_DIR") for n in _library_names()]
    found = ctypes.util.find_library("cdm")
    if found:
        out.append((found, "system (ctypes.util.find_library)"))
    out.append((_library_names()[0], "system (dynamic linker search path)"))
    return out


class _Missing:
    """Stands in for a function the loaded library does not export (an older
    or foreign build): calling it raises a CdmError naming the function."""

    def __init__(self, name: str, path: str) -> None:
        self.__name__ = name
        self._path = path

    def __call__(self, *args: Any) -> Any:
        raise CdmError(Error.CDM_ERR_UNSUPPORTED, "%s is not exported by %s" % (self.__name__, self._path),
                       function=self.__name__)


class Library:
    """The loaded libcdm with its prototypes applied: one attribute per
    function of PROTOTYPES, typed by what it returns (int for int and size_t,
    bytes or None for a C string, None for void)."""

    cdm_version: Callable[..., Optional[bytes]]
    cdm_version_number: Callable[..., int]
    cdm_strerror: Callable[..., Optional[bytes]]
    cdm_thread_error: Callable[..., Optional[bytes]]
    cdm_enumerate: Callable[..., int]
    cdm_device_list_count: Callable[..., int]
    cdm_device_list_get: Callable[..., int]
    cdm_device_list_free: Callable[..., None]
    cdm_open: Callable[..., int]
    cdm_open_ex: Callable[..., int]
    cdm_close: Callable[..., None]
    cdm_shutdown: Callable[..., int]
    cdm_get_pose: Callable[..., int]
    cdm_wait_pose: Callable[..., int]
    cdm_wait_pose_after: Callable[..., int]
    cdm_set_log_fn: Callable[..., None]
    cdm_get_raw: Callable[..., int]
    cdm_get_info: Callable[..., int]
    cdm_set_stale_timeout: Callable[..., int]
    cdm_get_stats: Callable[..., int]
    cdm_device_error: Callable[..., int]
    cdm_calibration_load: Callable[..., int]
    cdm_calibration_parse: Callable[..., int]
    cdm_calibration_free: Callable[..., None]
    cdm_calibration_position: Callable[..., int]
    cdm_calibration_lengths: Callable[..., int]
    cdm_calibration_position_covariance: Callable[..., int]
    cdm_calibration_effect_count: Callable[..., int]
    cdm_calibration_effect_name: Callable[..., Optional[bytes]]
    cdm_set_calibration: Callable[..., int]
    cdm_device_calibration_read: Callable[..., int]
    cdm_device_calibration_write: Callable[..., int]
    cdm_effect_register: Callable[..., int]
    cdm_effect_unregister: Callable[..., int]
    cdm_effect_load_plugin: Callable[..., int]
    cdm_effect_count: Callable[..., int]
    cdm_effect_name: Callable[..., Optional[bytes]]
    cdm_effect_fingerprint: Callable[..., int]
    cdm_diagnose: Callable[..., int]
    cdm_fit: Callable[..., int]
    cdm_check: Callable[..., int]
    cdm_plan: Callable[..., int]
    cdm_free_string: Callable[..., None]
    cdm_dataset_writer_open: Callable[..., int]
    cdm_dataset_writer_add: Callable[..., int]
    cdm_dataset_writer_add_at: Callable[..., int]
    cdm_dataset_writer_commit: Callable[..., int]
    cdm_dataset_writer_free: Callable[..., None]
    cdm_device_info_report: Callable[..., int]
    cdm_sim_truth: Callable[..., int]
    cdm_recorder_open: Callable[..., int]
    cdm_recorder_write: Callable[..., int]
    cdm_recorder_close: Callable[..., int]
    cdm_recorder_open_ex: Callable[..., int]
    cdm_recorder_write_sample: Callable[..., int]
    cdm_recorder_write_rejected: Callable[..., int]
    cdm_jig_plan_create: Callable[..., int]
    cdm_jig_plan_count: Callable[..., int]
    cdm_jig_plan_samples: Callable[..., int]
    cdm_jig_plan_get: Callable[..., int]
    cdm_jig_plan_use_file: Callable[..., int]
    cdm_jig_plan_samples_at: Callable[..., int]
    cdm_jig_plan_plate: Callable[..., int]
    cdm_plan_file_read: Callable[..., int]
    cdm_jig_plan_free: Callable[..., None]
    cdm_effect_doc: Callable[..., Optional[bytes]]
    cdm_effect_param_count: Callable[..., int]
    cdm_effect_param: Callable[..., int]
    cdm_nominal_device_json: Callable[..., int]
    cdm_device_file_read: Callable[..., int]
    cdm_simulate_jig_defaults: Callable[..., int]
    cdm_simulate_jig_dataset: Callable[..., int]
    cdm_write_file_atomic: Callable[..., int]
    cdm_watch: Callable[..., int]
    cdm_watch_free: Callable[..., None]

    def __init__(self, cdll: ctypes.CDLL, path: str) -> None:
        self.cdll = cdll
        self.path = path
        self.missing: List[str] = []
        for name, (restype, argtypes) in PROTOTYPES.items():
            try:
                fn = getattr(cdll, name)
            except AttributeError:
                self.missing.append(name)
                setattr(self, name, _Missing(name, path))
                continue
            fn.restype = restype
            fn.argtypes = argtypes
            setattr(self, name, fn)


def load(cands: Optional[Sequence[Tuple[str, str]]] = None) -> Library:
    """Loads libcdm from the first candidate that works; LibraryNotFoundError lists them all."""
    tried: List[Tuple[str, str]] = []
    for path, origin in (candidates() if cands is None else cands):
        label = "%s (%s)" % (path, origin)
        if os.sep in path and not os.path.exists(path):
            tried.append((label, "no such file"))
            continue
        try:
            cdll = ctypes.CDLL(path)
        except OSError as e:
            tried.append((label, str(e)))
            continue
        try:
            fn = cdll.cdm_version_number
        except AttributeError:
            tried.append((label, "not libcdm (no cdm_version_number)"))
            continue
        fn.restype, fn.argtypes = ctypes.c_int, []
        major = int(fn()) // 10000
        if major != CDM_VERSION_MAJOR:
            tried.append((label, "major version %d, this binding needs %d" % (major, CDM_VERSION_MAJOR)))
            continue
        return Library(cdll, getattr(cdll, "_name", path))
    raise LibraryNotFoundError(tried)


_lib: Optional[Library] = None
_lib_lock = threading.Lock()


def lib() -> Library:
    """The process's libcdm, loaded on first use (so that `import cdm` works without it)."""
    global _lib
    if _lib is None:
        with _lib_lock:
            if _lib is None:
                _lib = load()
    return _lib


def text(value: Optional[bytes]) -> str:
    """A C string the library returned, decoded ("" for NULL; invalid UTF-8 replaced)."""
    return (value or b"").decode("utf-8", "replace")


def c_path(value: Union[str, bytes, "os.PathLike[str]", "os.PathLike[bytes]"], what: str = "path") -> bytes:
    """A str, bytes or os.PathLike as the NUL-terminated bytes C receives.

    An embedded NUL would silently cut the string where C reads it ("a\\x00b"
    would open "a"), so it is a ValueError naming `what`.
    """
    data = os.fsencode(value) if not isinstance(value, bytes) else value
    if b"\x00" in data:
        raise ValueError(f"{what} contains a NUL character: {value!r}")
    return data


def fail(code: int, function: str, detail: str = "") -> CdmError:
    """The CdmError for a failed call. Call it right after the call: the thread's
    detail text is valid only until this thread's next cdm_* call."""
    L = lib()
    if not detail:
        detail = text(L.cdm_thread_error())
    message = text(L.cdm_strerror(code))
    return CdmError(code, "%s: %s" % (message, detail) if detail else message, detail, function)


def check(code: int, function: str) -> int:
    """Raises the CdmError for a negative code; returns the code otherwise."""
    if code < 0:
        raise fail(code, function)
    return code


_C = TypeVar("_C", bound="Closing")


class Closing:
    """A handle that frees its native object on close(), idempotently; as a
    context manager and at garbage collection too. Subclasses define close()."""

    def close(self) -> None:
        """Frees the native object (idempotent)."""
        raise NotImplementedError

    def __enter__(self: "_C") -> "_C":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:
            pass
