// Tests of Cdm.dll under Mono. Exit code = number of failed checks.
//   mono CdmTests.exe ROOT layout      struct layouts against tests/data/abi_layout.json
//   mono CdmTests.exe ROOT constants   enums against include/cdm/cdm.h
//   mono CdmTests.exe ROOT device      the simulated master through the binding
//   mono CdmTests.exe ROOT watch       Cdm.Watcher on the emulated master (umockdev_csharp_watch)
using System;
using System.Collections.Generic;
using System.IO;
using System.Linq;
using System.Reflection;
using System.Runtime.InteropServices;
using System.Text.RegularExpressions;
using System.Threading;
using Cdm;

static partial class CdmTests
{
    static int failures;
    static int checks;

    static void Expect(bool ok, string what)
    {
        checks++;
        if (!ok) { failures++; Console.WriteLine("FAIL: " + what); }
    }

    static void Run(string name, Action test)
    {
        try { test(); Console.WriteLine("ran  " + name); }
        catch (Exception e) { failures++; Console.WriteLine("FAIL: " + name + " threw " + e); }
    }

    static int Main(string[] args)
    {
        if (args.Length < 2) { Console.Error.WriteLine("usage: CdmTests.exe SOURCE_ROOT layout|constants|device..."); return 100; }
        string root = args[0];
        foreach (var group in args.Skip(1))
        {
            switch (group)
            {
                case "layout": Run("layout", () => Layout(Path.Combine(root, "tests", "data", "abi_layout.json"))); break;
                case "constants": Run("constants", () => Constants(Path.Combine(root, "include", "cdm", "cdm.h"))); break;
                case "device":
                    Run("open_and_read", OpenAndRead);
                    Run("dispose_is_idempotent", DisposeIsIdempotent);
                    Run("bad_uri", BadUri);
                    Run("sample_callback", SampleCallback);
                    Run("events_and_log", EventsAndLog);
                    Run("dispose_wakes_blocked_waiter", DisposeWakesBlockedWaiter);
                    Run("dispose_inside_sample_callback", DisposeInsideSampleCallback);
                    Run("dispose_inside_event_callback", DisposeInsideEventCallback);
                    Run("dispose_inside_log_sink", DisposeInsideLogSink);
                    Run("wait_inside_own_callback_refused", WaitInsideOwnCallbackRefused);
                    Run("callback_may_call_its_device", CallbackMayCallItsDevice);
                    break;
                case "missing_dependency": Run("missing_dependency", () => MissingDependency(args[0])); break;
                case "watch": Run("watch_replug", WatchReplug); break; // under with_master --replug (tests/umockdev)
                case "calibration":
                    Run("calibration_errors", CalibrationErrors);
                    Run("geometry_effect", GeometryEffect);
                    Run("frames", FramesCarryRotations);
                    break;
                default: Console.Error.WriteLine("unknown group " + group); return 100;
            }
        }
        Console.WriteLine("{0} checks, {1} failed", checks, failures);
        return Math.Min(failures, 99);
    }

    // Run with a libcdm.so.1 beside Cdm.dll whose own dependency is absent
    // (tests/csharp/missing_dependency.sh): the exception names that dependency.
    static void MissingDependency(string missing)
    {
        try { Device.Open("sim:").Dispose(); Expect(false, "missing_dependency: Open succeeded"); }
        catch (DllNotFoundException e)
        {
            Expect(e.Message.Contains(missing), "missing_dependency: the message names " + missing + ": " + e.Message);
            Console.WriteLine(e.Message);
        }
    }

    // since 1.1: a stall is reported once as Stale; libcdm's messages arrive
    // through Cdm.Log.Message (a failing call's detail at level 0, debug).
    static void EventsAndLog()
    {
        var seen = new List<DeviceEvent>();
        using (var dev = Device.Open("sim:?stall_after=30", 0, null, (kind, text) => { lock (seen) seen.Add(kind); }))
        {
            var until = DateTime.UtcNow.AddSeconds(2);
            while (DateTime.UtcNow < until) { lock (seen) if (seen.Contains(DeviceEvent.Stale)) break; Thread.Sleep(10); }
        }
        lock (seen) Expect(seen.Count(k => k == DeviceEvent.Stale) == 1, "events: one Stale on a stall");
        var logs = new List<string>();
        Action<int, string> h = (level, msg) => { lock (logs) logs.Add(level + ":" + msg); };
        Log.Message += h;
        try { Device.Open("nosuch:").Dispose(); } catch (CdmException) { }
        Log.Message -= h;
        lock (logs) Expect(logs.Any(l => l.StartsWith("0:") && l.Contains("nosuch")), "log: the failing open's detail at debug");
    }

    // A vector rotated in the device frame and carried into ROS's or Unity's
    // equals the carried vector rotated by the carried quaternion (the
    // component formula both engines apply); exact up to rounding.
    static double[] QRot(double[] q, double[] v)
    {
        double x = q[0], y = q[1], z = q[2], w = q[3];
        double[] c1 = { y * v[2] - z * v[1], z * v[0] - x * v[2], x * v[1] - y * v[0] };
        double[] c2 = { y * c1[2] - z * c1[1], z * c1[0] - x * c1[2], x * c1[1] - y * c1[0] };
        return new[] { v[0] + 2 * w * c1[0] + 2 * c2[0], v[1] + 2 * w * c1[1] + 2 * c2[1], v[2] + 2 * w * c1[2] + 2 * c2[2] };
    }

    static void FramesCarryRotations()
    {
        var rng = new Random(7);
        foreach (var frame in new[] { Cdm.Frames.RosFromDevice, Cdm.Frames.UnityFromDevice })
            for (int k = 0; k < 100; ++k)
            {
                double[] q = { rng.NextDouble() - 0.5, rng.NextDouble() - 0.5, rng.NextDouble() - 0.5, rng.NextDouble() - 0.5 };
                double n = Math.Sqrt(q.Sum(c => c * c));
                var pose = new Cdm.Pose();
                pose.Orientation = new Cdm.Quaterniond(q[3] / n, q[0] / n, q[1] / n, q[2] / n);
                pose.Position = new Cdm.Vector3d(rng.NextDouble() * 100, rng.NextDouble() * 100 - 50, rng.NextDouble() * 100 - 50);
                Cdm.Vector3d pm;
                double[] q2;
                Cdm.Frames.ToFrame(pose, frame, out pm, out q2);
                double[] dev = { pose.Orientation.X, pose.Orientation.Y, pose.Orientation.Z, pose.Orientation.W };
                double[] r = QRot(dev, pose.Position.ToArray());
                double[] a = { 0, 0, 0 };
                for (int i = 0; i < 3; ++i) a[i] = frame[i, 0] * r[0] + frame[i, 1] * r[1] + frame[i, 2] * r[2];
                double[] b = QRot(q2, new[] { pm.X * 1000, pm.Y * 1000, pm.Z * 1000 });
                for (int i = 0; i < 3; ++i) Expect(Math.Abs(a[i] - b[i]) < 1e-9, "frames: rotation carried, axis " + i);
            }
        var p0 = new Cdm.Pose();
        p0.Position = new Cdm.Vector3d(100, 20, 30);
        p0.Orientation = new Cdm.Quaterniond(1, 0, 0, 0);
        Cdm.Vector3d ros, unity;
        double[] qr, qu;
        Cdm.Frames.ToRos(p0, out ros, out qr);
        Cdm.Frames.ToUnity(p0, out unity, out qu);
        Expect(Math.Abs(ros.X + 0.1) < 1e-12 && Math.Abs(ros.Y + 0.02) < 1e-12 && Math.Abs(ros.Z - 0.03) < 1e-12, "frames: ROS axes");
        Expect(Math.Abs(unity.X - 0.02) < 1e-12 && Math.Abs(unity.Y - 0.03) < 1e-12 && Math.Abs(unity.Z + 0.1) < 1e-12, "frames: Unity axes");
        Expect(qr[3] == 1 && qu[3] == 1, "frames: identity stays identity");
    }

    // ------------------------------------------------------------ hot-plug
    // Run by `with_master --replug 300,400 --after-output Arrived`
    // (tests/umockdev: the unplug comes 300 ms after the first event is
    // printed): the master there at the start arrives, leaves at the unplug,
    // arrives at the replug; Dispose from the callback throws; nothing after
    // Dispose.
    static void WatchReplug()
    {
        var seen = new List<string>();
        var gate = new object();
        var three = new ManualResetEvent(false);
        Watcher holder = null;
        bool disposeRefused = false;
        var w = Watcher.Start((kind, info) =>
        {
            Watcher h;
            lock (gate)
            {
                seen.Add(kind + " " + info.Uri + " " + info.Serial);
                Console.WriteLine("watch event: " + kind + " " + info.Uri); // with_master's cue (Console.Out flushes)
                h = holder;
                if (seen.Count >= 3) three.Set();
            }
            if (kind == WatchEvent.Left && h != null)
            {
                try { h.Dispose(); }
                catch (InvalidOperationException) { disposeRefused = true; }
            }
        }, true);
        lock (gate) holder = w;
        Expect(three.WaitOne(15000), "watch: three events within 15 s");
        w.Dispose();
        Expect(w.IsDisposed, "watch: disposed");
        int n;
        lock (gate) n = seen.Count;
        Thread.Sleep(200);
        lock (gate)
        {
            Expect(seen.Count == n, "watch: no callback after Dispose");
            Expect(string.Join("; ", seen) == "Arrived hid:/dev/hidraw0 UMOCK0001; Left hid:/dev/hidraw0 UMOCK0001; Arrived hid:/dev/hidraw0 UMOCK0001",
                   "watch: got " + string.Join("; ", seen));
        }
        Expect(disposeRefused, "watch: Dispose from the callback throws InvalidOperationException");
    }

    // ------------------------------------------------------------ layouts
    static void Layout(string jsonPath)
    {
        var table = (Dictionary<string, object>)((Dictionary<string, object>)Json.Parse(File.ReadAllText(jsonPath)))["structs"];
        var mirrors = new Dictionary<string, Type>();
        foreach (var t in typeof(Device).Assembly.GetTypes())
        {
            foreach (var a in t.GetCustomAttributes(false))
                if (a.GetType().Name == "CStructAttribute")
                    mirrors[(string)a.GetType().GetField("Name").GetValue(a)] = t;
        }
        Expect(mirrors.Count == table.Count, "C# mirrors " + mirrors.Count + " structs, the table has " + table.Count);
        foreach (var kv in table)
        {
            Type t;
            if (!mirrors.TryGetValue(kv.Key, out t)) { Expect(false, kv.Key + " has no C# mirror"); continue; }
            var entry = (Dictionary<string, object>)kv.Value;
            int size = Marshal.SizeOf(t);
            Expect(size == Convert.ToInt32(entry["size"]), kv.Key + ": Marshal.SizeOf " + size + ", table " + entry["size"]);
            var fields = (Dictionary<string, object>)entry["fields"];
            var csFields = t.GetFields(BindingFlags.Public | BindingFlags.Instance).Select(f => f.Name).ToList();
            foreach (var f in fields)
            {
                string name = csFields.Contains(f.Key) ? f.Key : f.Key + "_0";
                if (!csFields.Contains(name)) { Expect(false, kv.Key + "." + f.Key + " has no C# field"); continue; }
                long off = Marshal.OffsetOf(t, name).ToInt64();
                Expect(off == Convert.ToInt64(f.Value), kv.Key + "." + f.Key + ": OffsetOf " + off + ", table " + f.Value);
            }
            // Every C# field is one of the table's (or an element of one of its arrays).
            foreach (var n in csFields)
                Expect(fields.ContainsKey(Regex.Replace(n, "_[0-9]+$", "")) || fields.ContainsKey(n),
                       kv.Key + ": C# field " + n + " is not in the table");
        }
    }

    // ---------------------------------------------------------- constants
    static void Constants(string headerPath)
    {
        var src = File.ReadAllText(headerPath);
        var found = 0;
        foreach (Match m in Regex.Matches(src, @"\b(CDM_(ERR|POSE|BUTTON)_(\w+)|CDM_OK)\s*=\s*([^,\n/]+)"))
        {
            string expr = m.Groups[4].Value.Trim().Replace("u", "");
            var shift = Regex.Match(expr, @"^(\d+)\s*<<\s*(\d+)$");
            long value = shift.Success ? long.Parse(shift.Groups[1].Value) << int.Parse(shift.Groups[2].Value) : long.Parse(expr);
            string kind = m.Groups[2].Success ? m.Groups[2].Value : "ERR";
            string pascal = m.Groups[3].Success
                ? string.Concat(m.Groups[3].Value.Split('_').Select(w => w.Substring(0, 1) + w.Substring(1).ToLowerInvariant()))
                : "Ok";
            Type e = kind == "ERR" ? typeof(ErrorCode) : kind == "POSE" ? typeof(PoseFlags) : typeof(Buttons);
            string match = Enum.GetNames(e).FirstOrDefault(n => string.Equals(n, pascal, StringComparison.OrdinalIgnoreCase));
            if (match == null) { Expect(false, m.Groups[1].Value + " has no member in " + e.Name); continue; }
            long cs = Convert.ToInt64(Enum.Parse(e, match));
            Expect(cs == value, m.Groups[1].Value + ": header " + value + ", C# " + e.Name + "." + match + " = " + cs);
            found++;
        }
        Expect(found == 17 + 6 + 3, "parsed " + found + " constants from the header, expected 26");
        Expect(Enum.GetValues(typeof(ErrorCode)).Length == 17, "ErrorCode has a member the header lacks");
        Expect(Device.LibraryVersion == "1.0.0" || Device.LibraryVersion.StartsWith("1."), "library version " + Device.LibraryVersion);
    }

    // ------------------------------------------------------------- device
    static void OpenAndRead()
    {
        using (var dev = Device.Open("sim:?motion=still&noise=0&imu_noise=0&hall_noise=0"))
        {
            var p = dev.WaitPose(1000);
            var info0 = dev.GetInfo();
            var raw0 = dev.GetRaw();
            Expect(p.Status == ErrorCode.Ok, "first pose status " + p.Status);
            Pose tp;
            Expect(dev.TryGetPose(out tp) && (tp.Status == ErrorCode.Ok || tp.Status == ErrorCode.Stale),
                   "TryGetPose: true with a pose, status " + tp.Status);
            // motion=still holds the holder at (50, 0, 0) mm. With noise off the only
            // error is the pots' quantisation, +-scale/2 per cable, which moves the
            // holder by at most dl * L / x (out of the plane, the worst direction).
            double tol = 0.5 * info0.PotScaleMm.Max() * raw0.LengthsMm.Max() / 50.0 * 1.01;
            Expect(Math.Abs(p.Position.X - 50) <= tol && Math.Abs(p.Position.Y) <= tol && Math.Abs(p.Position.Z) <= tol,
                   "still pose at " + p.Position + ", tolerance " + tol + " mm");
            // Level grip, q14-quantised: each component within half a count.
            double qtol = 0.5 / 16384 + 1e-12;
            Expect(Math.Abs(p.Orientation.W - 1) <= qtol && Math.Abs(p.Orientation.X) <= qtol &&
                   Math.Abs(p.Orientation.Y) <= qtol && Math.Abs(p.Orientation.Z) <= qtol, "level grip, got " + p.Orientation);
            var q = dev.WaitPose(1000);
            Expect(q.Sequence != p.Sequence && q.HostTimeNs > p.HostTimeNs, "WaitPose returns a newer pose");
            // No lost wake-up: a pose newer than p already exists, so this returns at once.
            var a = dev.WaitPoseAfter(p.HostSequence, 0);
            Expect(a.HostSequence > p.HostSequence, "WaitPoseAfter(" + p.HostSequence + ") gave " + a.HostSequence);
            var g = dev.GetPose();
            Expect(g.Sequence - q.Sequence < 1000, "GetPose sequence " + g.Sequence + " after " + q.Sequence);
            var info = dev.GetInfo();
            Expect(info.Transport == "sim", "transport " + info.Transport);
            Expect(info.ReportRateHz > 0 && info.PotScaleMm.Length == 4, "info rate " + info.ReportRateHz);
            var raw = dev.GetRaw();
            Expect(raw.LengthsMm.All(l => l > 0), "raw lengths " + string.Join(",", raw.LengthsMm));
            var stats = dev.GetStats();
            Expect(stats.Reports >= 2, "stats.Reports " + stats.Reports);
        }
    }

    static void DisposeIsIdempotent()
    {
        var dev = Device.Open("sim:");
        dev.Dispose();
        dev.Dispose();
        Expect(dev.IsDisposed, "IsDisposed after Dispose");
        try { dev.GetPose(); Expect(false, "GetPose after Dispose did not throw"); }
        catch (ObjectDisposedException) { }
    }

    static void BadUri()
    {
        try
        {
            Device.Open("nosuchscheme:xyz").Dispose();
            Expect(false, "Open(nosuchscheme:xyz) did not throw");
        }
        catch (CdmException e)
        {
            Expect(e.Code == ErrorCode.NoDevice || e.Code == ErrorCode.InvalidArg, "code " + e.Code);
            Expect(e.Message.Contains("nosuchscheme"), "message names the URI: " + e.Message);
            Expect(e.Function == "cdm_open", "function " + e.Function);
        }
    }

    static void SampleCallback()
    {
        int n = 0;
        long lastSequence = -1, outOfOrder = 0;
        using (var dev = Device.Open("sim:", 0, p =>
        {
            if (p.Sequence <= lastSequence) outOfOrder++;
            lastSequence = p.Sequence;
            Interlocked.Increment(ref n);
        }))
        {
            // Collect garbage while the reader thread calls back: the delegate must survive.
            for (int i = 0; i < 5; i++) { GC.Collect(); GC.WaitForPendingFinalizers(); dev.WaitPose(1000); }
        }
        int after = n;
        Thread.Sleep(50);
        Expect(after >= 5, "callback ran " + after + " times");
        Expect(n == after, "callback ran after Dispose");
        Expect(outOfOrder == 0, outOfOrder + " samples out of order");
    }

    // since 1.2: a geometry-aware effect on the cable's path registered from C#
    // (Cdm.Effects, its delegate kept alive by the binding): the calibration's
    // lengths are the nominal chords plus the sag the delegate computes from the
    // geometry it is given, checked against the same physics from the drawing
    // (a = b = 150, m = 30: anchors (0, +-a, +-b), holder corners (0, +-m/2, +-m/2)).
    static void GeometryEffect()
    {
        const double c = 4e-8;
        int calls = 0;
        Effects.Register("cs_sag", new[] { "c_per_mm2" }, new[] { 1e-8 }, (prm, g, v) =>
        {
            calls++;
            for (int i = 0; i < g.Count; i++)
                for (int k = 0; k < 4; k++)
                {
                    double uz = g.Unit[(4 * i + k) * 3 + 2], L = g.Chord[4 * i + k];
                    v[4 * i + k] += prm[0] * L * L * L * (1 - uz * uz);
                }
        }, EffectStage.Path, new[] { "1/mm^2" }, new[] { 0.0 }, new[] { 1e-6 });
        Expect(Array.IndexOf(Effects.Names, "cs_sag") >= 0, "cs_sag registered");
        Expect(Regex.IsMatch(Effects.Fingerprint("cs_sag"), "^[0-9a-f]{16}$"), "fingerprint " + Effects.Fingerprint("cs_sag"));
        var json = "{\"format\": \"cdm-calibration\", \"version\": 1, \"device\": {\"a_mm\": 150, \"b_mm\": 150, " +
                   "\"m_mm\": 30}, \"effects\": [{\"name\": \"cs_sag\", \"params\": {\"c_per_mm2\": 4e-8}}]}";
        using (var cal = Calibration.Parse(json))
        {
            var p = new Vector3d(50, 10, -20);
            var l = cal.Lengths(p);
            double[] sy = { 1, 1, -1, -1 }, sz = { -1, 1, -1, 1 };
            for (int k = 0; k < 4; k++)
            {
                double dx = p.X, dy = p.Y + 15 * sy[k] - 150 * sy[k], dz = p.Z + 15 * sz[k] - 150 * sz[k];
                double L = Math.Sqrt(dx * dx + dy * dy + dz * dz), uz = dz / L;
                double want = L + c * L * L * L * (1 - uz * uz);
                // A few roundings of ~200 mm numbers.
                Expect(Math.Abs(l[k] - want) < 1e-9, "cable " + k + ": " + l[k] + " vs " + want);
            }
        }
        Expect(calls > 0, "the delegate was called");
        Effects.Unregister("cs_sag");
        // A delegate that throws fails the evaluation with a code, not a crash.
        Effects.Register("cs_throws", new string[0], new double[0], (prm, g, v) => { throw new InvalidOperationException("boom"); },
                         EffectStage.Reading);
        var bad = "{\"format\": \"cdm-calibration\", \"version\": 1, \"device\": {\"a_mm\": 150, \"b_mm\": 150, " +
                  "\"m_mm\": 30}, \"effects\": [{\"name\": \"cs_throws\", \"params\": {}}]}";
        using (var cal = Calibration.Parse(bad))
        {
            try { cal.Lengths(new Vector3d(50, 0, 0)); Expect(false, "a throwing delegate gave lengths"); }
            catch (CdmException) { }
        }
        Expect(Effects.LastError("cs_throws") is InvalidOperationException, "the exception is kept");
        Effects.Unregister("cs_throws");
        try
        {
            Effects.Register("cs_dup", new[] { "a", "a" }, new[] { 1.0, 1.0 }, (prm, g, v) => { });
            Expect(false, "duplicate parameter names accepted");
        }
        catch (ArgumentException e) { Expect(e.Message.Contains("given twice"), e.Message); }
    }

    static void CalibrationErrors()
    {
        var path = Path.Combine(Path.GetTempPath(), "cdm-cs-bad-" + Guid.NewGuid().ToString("N") + ".json");
        File.WriteAllText(path, "{\n  \"geometry\": [1, 2,\n");
        try
        {
            Calibration.Load(path).Dispose();
            Expect(false, "Load of a truncated file did not throw");
        }
        catch (CdmException e)
        {
            Expect(e.Code == ErrorCode.Parse, "code " + e.Code);
            Expect(e.Message.Contains(path), "message names the file: " + e.Message);
        }
        finally { File.Delete(path); }
    }
}

/// <summary>Just enough JSON for the layout table: objects, arrays, strings, numbers.</summary>
static class Json
{
    public static object Parse(string s) { int i = 0; var v = Value(s, ref i); return v; }

    static void Ws(string s, ref int i) { while (i < s.Length && char.IsWhiteSpace(s[i])) i++; }

    static object Value(string s, ref int i)
    {
        Ws(s, ref i);
        char c = s[i];
        if (c == '{')
        {
            var d = new Dictionary<string, object>();
            i++; Ws(s, ref i);
            if (s[i] == '}') { i++; return d; }
            while (true)
            {
                Ws(s, ref i);
                var k = (string)Value(s, ref i);
                Ws(s, ref i);
                if (s[i++] != ':') throw new FormatException("':' expected at " + i);
                d[k] = Value(s, ref i);
                Ws(s, ref i);
                if (s[i] == ',') { i++; continue; }
                if (s[i++] == '}') return d;
                throw new FormatException("',' or '}' expected at " + i);
            }
        }
        if (c == '[')
        {
            var l = new List<object>();
            i++; Ws(s, ref i);
            if (s[i] == ']') { i++; return l; }
            while (true)
            {
                l.Add(Value(s, ref i));
                Ws(s, ref i);
                if (s[i] == ',') { i++; continue; }
                if (s[i++] == ']') return l;
                throw new FormatException("',' or ']' expected at " + i);
            }
        }
        if (c == '"')
        {
            var sb = new System.Text.StringBuilder();
            i++;
            while (s[i] != '"') { if (s[i] == '\\') i++; sb.Append(s[i++]); }
            i++;
            return sb.ToString();
        }
        int start = i;
        while (i < s.Length && "+-0123456789.eE".IndexOf(s[i]) >= 0) i++;
        if (i == start) throw new FormatException("unexpected '" + c + "' at " + i);
        return double.Parse(s.Substring(start, i - start), System.Globalization.CultureInfo.InvariantCulture);
    }
}
