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
