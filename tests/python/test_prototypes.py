"""Every function of cdm.h has a prototype in the binding, with matching types."""
import ctypes

import cdm
import header
from cdm import _native


def _kind_c(t):
    if t == "void":
        return "void"
    if t.endswith("_fn"):
        return "fnptr"
    if "*" in t:
        return "char*" if t.replace("const", "").split() == ["char", "*"] else "ptr"
    if t == "uint64_t" and ctypes.c_uint64 is ctypes.c_size_t:
        return "size_t"  # one ctypes type on LP64: the binding cannot say which it meant
    return t.replace("const ", "")


def _kind_py(ct):
    if ct is None:
        return "void"
    if ct is ctypes.c_char_p:
        return "char*"
    if isinstance(ct, type) and issubclass(ct, ctypes._CFuncPtr):
        return "fnptr"
    if ct is ctypes.c_void_p or (isinstance(ct, type) and issubclass(ct, ctypes._Pointer)):
        return "ptr"
    return {ctypes.c_int: "int", ctypes.c_size_t: "size_t", ctypes.c_uint32: "uint32_t",
            ctypes.c_double: "double"}.get(ct, repr(ct))


def test_parser_sees_the_header():
    f = header.functions()
    assert f["cdm_wait_pose"] == ("int", ["cdm_device *", "int", "cdm_pose *"])
    assert f["cdm_calibration_position"][1] == ["const cdm_calibration *", "const double *", "double *"]
    assert len(f) >= 35


def test_same_functions():
    assert set(header.functions()) == set(_native.PROTOTYPES)


def test_same_types():
    for name, (ret, params) in header.functions().items():
        restype, argtypes = _native.PROTOTYPES[name]
        assert _kind_py(restype) == _kind_c(ret), "%s returns %s" % (name, ret)
        assert len(argtypes) == len(params), "%s takes %d arguments" % (name, len(params))
        for i, (p, a) in enumerate(zip(params, argtypes)):
            expect = _kind_c(p)
            got = _kind_py(a)
            # char* parameters that the library writes into (buffers, char** out) are pointers too.
            if expect == "char*" and "const" not in p and got == "char*":
                got = "char*"
            if expect == "uint64_t" and got == "size_t" and ctypes.sizeof(ctypes.c_size_t) == 8:
                got = "uint64_t"  # one ctypes type on LP64
            assert got == expect or (expect == "char*" and got == "ptr" and "const" not in p), \
                "%s argument %d: header %r, binding %r" % (name, i, p, a)


def test_library_exports_every_function(lib):
    assert lib.missing == [], "libcdm at %s lacks %s" % (lib.path, lib.missing)


def test_prototypes_applied(lib):
    assert lib.cdm_wait_pose.argtypes == _native.PROTOTYPES["cdm_wait_pose"][1]
    assert lib.cdm_strerror.restype is ctypes.c_char_p
    assert cdm.version()
