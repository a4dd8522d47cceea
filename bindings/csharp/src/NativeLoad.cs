// Why libcdm did not load. Mono's DllNotFoundException names only the library
// it was asked for ("libcdm.so.1"), even when that file is right there and one
// of its own dependencies (libnlopt, libhidapi) is what is missing. The first
// call of each public entry point goes through EnsureLoaded: on that failure it
// asks the dynamic linker itself (dlopen, dlerror) at each place Mono looks,
// and rethrows with the linker's reason, which names the library actually missing.
using System;
using System.Collections.Generic;
using System.IO;
using System.Runtime.InteropServices;

namespace Cdm
{
    internal static class NativeLoad
    {
        static volatile bool loaded;

        [DllImport("libdl.so.2")] static extern IntPtr dlopen(string file, int mode);
        [DllImport("libdl.so.2")] static extern IntPtr dlerror();
        [DllImport("libdl.so.2")] static extern int dlclose(IntPtr handle);
        const int RTLD_NOW = 2;

        /// <summary>Loads libcdm (once); a DllNotFoundException names what the dynamic linker missed.</summary>
        internal static void EnsureLoaded()
        {
            if (loaded) return;
            try { NativeMethods.cdm_version_number(); }
            catch (DllNotFoundException e) { throw new DllNotFoundException(Explain(e.Message), e); }
            loaded = true;
        }

        /// <summary>The dynamic linker's reasons for every place libcdm is looked for.</summary>
        internal static string Explain(string monoMessage)
        {
            var lines = new List<string>();
            foreach (var candidate in Candidates())
            {
                string reason = TryLoad(candidate);
                lines.Add(candidate + ": " + (reason ?? "loads when opened directly (so Mono looked elsewhere: check Cdm.dll.config's dllmap)"));
            }
            return "libcdm could not be loaded (" + monoMessage + "); the dynamic linker says:" + Environment.NewLine
                + "  " + string.Join(Environment.NewLine + "  ", lines.ToArray()) + Environment.NewLine
                + "libcdm needs libhidapi-hidraw0, libnlopt0, libudev1, libstdc++6 (Debian package names); "
                + "a missing one is named above.";
        }

        // Beside Cdm.dll (NuGet's copy-to-output, an installed tree), NuGet's
        // runtimes folder, then the linker's own search (LD_LIBRARY_PATH, ldconfig).
        static IEnumerable<string> Candidates()
        {
            string dir = null;
            try { dir = Path.GetDirectoryName(typeof(NativeLoad).Assembly.Location); } catch (Exception) { }
            if (!string.IsNullOrEmpty(dir))
            {
                foreach (var p in new[] { Path.Combine(dir, "libcdm.so.1"),
                                          Path.Combine(Path.Combine(Path.Combine(Path.Combine(dir, "runtimes"), "linux-x64"), "native"), "libcdm.so.1") })
                    if (File.Exists(p)) yield return p;
            }
            yield return "libcdm.so.1";
        }

        // null when it loads; otherwise dlerror()'s text.
        static string TryLoad(string file)
        {
            try
            {
                IntPtr h = dlopen(file, RTLD_NOW);
                if (h != IntPtr.Zero) { dlclose(h); return null; }
                IntPtr msg = dlerror();
                return msg == IntPtr.Zero ? "dlopen failed without a reason" : Marshal.PtrToStringAnsi(msg);
            }
            catch (Exception e) { return "could not ask the dynamic linker (" + e.GetType().Name + ")"; }
        }
    }
}
