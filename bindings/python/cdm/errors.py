"""The one exception class of the binding."""
from .constants import Error


class CdmError(Exception):
    """A libcdm call failed.

    code     the cdm_error value (negative int; compare with cdm.CDM_ERR_*)
    message  cdm_strerror(code), then the library's detail text (what was
             wrong and where: file:line:column, URI option, ...) when it gave one
    detail   the detail text alone ("" when none)
    function the C function that failed (e.g. "cdm_open"), or None
    """

    def __init__(self, code, message, detail="", function=None):
        super().__init__(code, message)
        self.code = int(code)
        self.message = message
        self.detail = detail
        self.function = function

    @property
    def name(self):
        """"CDM_ERR_NO_DEVICE" and so on; "unknown error <code>" for codes this binding does not know."""
        try:
            return Error(self.code).name
        except ValueError:
            return "unknown error %d" % self.code

    def __str__(self):
        where = "%s: " % self.function if self.function else ""
        return "%s%s (%s)" % (where, self.message, self.name)

    def __repr__(self):
        return "CdmError(%d, %r)" % (self.code, self.message)


class LibraryNotFoundError(OSError):
    """libcdm could not be loaded; .tried lists (path, reason) for every candidate, in order."""

    def __init__(self, tried):
        self.tried = list(tried)
        lines = ["libcdm could not be loaded; tried, in order:"]
        lines += ["  %s: %s" % (path, reason) for path, reason in self.tried]
        lines.append("Set CDM_LIBRARY to the library file (e.g. build/src/libcdm.so.1), or CDM_BUILD_DIR "
                     "to a build tree, or install libcdm (cmake --install).")
        super().__init__("\n".join(lines))
