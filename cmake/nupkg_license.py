"""Gives a packed .nupkg a licence expression: Debian's nuget (2.8) packs only
the deprecated <licenseUrl>, so its nuspec inside the package is rewritten to
what current NuGet writes for <license type="expression">: the expression and
the licenses.nuget.org URL beside it (for older clients).

    python3 nupkg_license.py PACKAGE.nupkg SPDX-EXPRESSION

The package is replaced through an exclusive temporary file in its directory
(written, fsynced, renamed): a failure leaves the original."""
import os
import re
import sys
import tempfile
import zipfile


def main(path: str, expression: str) -> int:
    with zipfile.ZipFile(path) as src:
        entries = [(info, src.read(info)) for info in src.infolist()]
    nuspecs = [i for i, (info, _) in enumerate(entries) if info.filename.endswith(".nuspec") and "/" not in info.filename]
    if len(nuspecs) != 1:
        print("nupkg_license: %s: expected one .nuspec at the top, found %d" % (path, len(nuspecs)), file=sys.stderr)
        return 1
    info, data = entries[nuspecs[0]]
    text = data.decode("utf-8")
    text, n = re.subn(r"<licenseUrl>[^<]*</licenseUrl>",
                      '<license type="expression">%s</license>'
                      "<licenseUrl>https://licenses.nuget.org/%s</licenseUrl>" % (expression, expression), text)
    if n != 1:
        print("nupkg_license: %s: %s has %d <licenseUrl> elements, expected 1" % (path, info.filename, n),
              file=sys.stderr)
        return 1
    entries[nuspecs[0]] = (info, text.encode("utf-8"))
    fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=".nupkg", dir=os.path.dirname(os.path.abspath(path)))
    try:
        with os.fdopen(fd, "wb") as f:
            with zipfile.ZipFile(f, "w", zipfile.ZIP_DEFLATED) as out:
                for i, d in entries:
                    out.writestr(i, d)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 3:
        print("usage: nupkg_license.py PACKAGE.nupkg SPDX-EXPRESSION", file=sys.stderr)
        sys.exit(2)
    sys.exit(main(sys.argv[1], sys.argv[2]))
