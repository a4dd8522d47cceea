#!/usr/bin/env bash
# Unpack the .nupkg as a consumer's restore would, lay the output directory
# out as NuGet's copy-to-output does (lib/netstandard2.0/* and
# runtimes/linux-x64/native/* beside the program), compile a tiny program
# against Cdm.dll with mcs and run it with mono on sim: with no
# LD_LIBRARY_PATH / MONO_PATH: Mono maps "cdm" to libcdm.so.1 through
# Cdm.dll.config and finds it beside the assembly.
set -euo pipefail
nupkg=$1 work=$2
unset LD_LIBRARY_PATH MONO_PATH CDM_LIBRARY
rm -rf "$work" && mkdir -p "$work/pkg" "$work/app"
cd "$work"
unzip -q "$nupkg" -d pkg
test -f pkg/lib/netstandard2.0/Cdm.dll
test -f pkg/runtimes/linux-x64/native/libcdm.so.1
# A licence expression (the URL beside it is the one NuGet writes for it), and
# the native dependencies declared in the description.
grep -q '<license type="expression">Apache-2.0</license>' pkg/Cdm.nuspec
if grep -o '<licenseUrl>[^<]*</licenseUrl>' pkg/Cdm.nuspec | grep -v 'licenses.nuget.org/Apache-2.0'; then
  echo "nuget.sh: a licenseUrl other than the expression's" >&2; exit 1
fi
for dep in libhidapi-hidraw.so.0 libnlopt.so.0 libudev.so.1; do grep -q "$dep" pkg/Cdm.nuspec; done
cp pkg/lib/netstandard2.0/* pkg/runtimes/linux-x64/native/* app/
cat > app/Use.cs <<'CS'
using System;
using Cdm;
static class Use {
    static int Main() {
        using (var d = Device.Open("sim:")) {
            Console.WriteLine("nuget: open sim: ok, library " + Device.LibraryVersion);
        }
        return 0;
    }
}
CS
mcs -nologo -r:app/Cdm.dll -out:app/Use.exe app/Use.cs
(cd / && mono "$work/app/Use.exe")
