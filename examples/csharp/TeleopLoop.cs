// TeleopLoop: the C# twin of examples/c/teleop_loop.c. A 1 kHz loop on
// Stopwatch deadlines reads the newest pose (Device.TryGetPose: no exception,
// no allocation), prints it at 10 Hz, and reports loop period and pose age.
//
//   mono TeleopLoop.exe [URI] [--seconds S]     URI default "sim:"; Ctrl-C stops it
//
// Sleeping precision is the OS timer's (about 1 ms on Linux), so the loop
// sleeps while more than 2 ms remain and spins the rest: a controller would
// run this on a dedicated thread (or core).
using System;
using System.Collections.Generic;
using System.Diagnostics;
using System.Runtime.InteropServices;
using System.Threading;
using Cdm;

static class TeleopLoop
{
    [StructLayout(LayoutKind.Sequential)]
    struct Timespec { public long tv_sec; public long tv_nsec; }

    [DllImport("libc", EntryPoint = "clock_gettime")]
    static extern int clock_gettime(int clock, out Timespec ts);

    // Pose.HostTimeNs is CLOCK_MONOTONIC (Linux: clock id 1). Stopwatch's epoch
    // is not specified to be the same, so ask libc directly.
    static long MonotonicNs()
    {
        Timespec ts;
        clock_gettime(1, out ts);
        return ts.tv_sec * 1000000000L + ts.tv_nsec;
    }

    static volatile bool stop;

    static double Percentile(List<double> sorted, double p)
    {
        int i = (int)Math.Ceiling(p / 100.0 * sorted.Count) - 1;
        return sorted[Math.Max(0, Math.Min(sorted.Count - 1, i))];
    }

    static int Main(string[] args)
    {
        string uri = "sim:";
        double seconds = 0;
        for (int i = 0; i < args.Length; i++)
        {
            if (args[i] == "--seconds" && i + 1 < args.Length)
            {
                if (!double.TryParse(args[++i], System.Globalization.NumberStyles.Float,
                                     System.Globalization.CultureInfo.InvariantCulture, out seconds) || !(seconds > 0))
                {
                    Console.Error.WriteLine("TeleopLoop: --seconds wants a positive number, got \"" + args[i] + "\"");
                    return 2;
                }
            }
            else if (args[i].StartsWith("--"))
            {
                Console.Error.WriteLine("usage: TeleopLoop.exe [URI] [--seconds S]");
                return 2;
            }
            else uri = args[i];
        }
        Console.CancelKeyPress += (s, e) => { e.Cancel = true; stop = true; };

        Device dev;
        try { dev = Device.Open(uri); }
        catch (CdmException e) { Console.Error.WriteLine("TeleopLoop: " + e.Message); return 1; }
        using (dev)
        {
            var first = dev.WaitPoseAfter(0, 2000); // the first pose, even one already published
            var info = dev.GetInfo();
            Console.WriteLine("opened {0} ({1}, serial {2}, firmware {3}, {4:F0} Hz reports), library {5}",
                              info.Uri, info.Transport, info.Serial, info.Firmware, info.ReportRateHz, Device.LibraryVersion);

            const int periodUs = 1000;
            long ticksPerPeriod = Stopwatch.Frequency * periodUs / 1000000;
            int maxCycles = seconds > 0 ? (int)(seconds * 1000) : int.MaxValue;
            var periods = new List<double>(Math.Min(maxCycles, 600000));
            var ages = new List<double>(Math.Min(maxCycles, 600000));
            long fresh = 0, stale = 0, errors = 0, overruns = 0;
            uint lastSeq = first.Sequence;
            var sw = Stopwatch.StartNew();
            long deadline = 0, prevWake = -1;
            Pose pose = first;
            for (int cycle = 0; cycle < maxCycles && !stop; cycle++)
            {
                deadline += ticksPerPeriod;
                long remaining;
                while ((remaining = deadline - sw.ElapsedTicks) > 0)
                {
                    if (remaining > 2 * ticksPerPeriod) Thread.Sleep(1);
                    else Thread.SpinWait(20);
                }
                long wake = sw.ElapsedTicks;

                dev.TryGetPose(out pose); // pose.Status: the C code
                int rc = (int)pose.Status;
                long readAt = MonotonicNs();
                if (rc == 0 || rc == (int)ErrorCode.Stale || rc == (int)ErrorCode.Disconnected)
                {
                    ages.Add((readAt - (long)pose.HostTimeNs) / 1000.0);
                    if (pose.Sequence != lastSeq) fresh++;
                    lastSeq = pose.Sequence;
                    if (rc != 0) stale++;
                }
                else if (rc == (int)ErrorCode.EndOfStream) { Console.WriteLine("end of stream"); break; }
                else errors++;

                if (prevWake >= 0) periods.Add((wake - prevWake) * 1e6 / Stopwatch.Frequency);
                prevWake = wake;
                if (wake - deadline > ticksPerPeriod)
                {
                    overruns++; // skip the missed cycles instead of bursting them
                    deadline = wake - (wake - deadline) % ticksPerPeriod;
                }
                if (cycle % 100 == 99) Console.WriteLine("t={0,6:F2}s {1}", sw.Elapsed.TotalSeconds, pose);
            }
            var stats = dev.GetStats();
            Console.WriteLine();
            Console.WriteLine("{0} after {1:F2} s, {2} cycles", stop ? "stopped (Ctrl-C)" : "done", sw.Elapsed.TotalSeconds, periods.Count + 1);
            if (periods.Count < 2 || ages.Count == 0)
            {
                Console.Error.WriteLine("TeleopLoop: too few cycles for statistics");
                return 1;
            }
            double mean = 0, m2 = 0, jitter = 0;
            for (int i = 0; i < periods.Count; i++)
            {
                double d = periods[i] - mean;
                mean += d / (i + 1);
                m2 += d * (periods[i] - mean);
                jitter = Math.Max(jitter, Math.Abs(periods[i] - periodUs));
            }
            ages.Sort();
            Console.WriteLine("loop period: mean {0:F1} us, std {1:F1} us, max jitter {2:F1} us, overruns {3}",
                              mean, Math.Sqrt(m2 / Math.Max(1, periods.Count - 1)), jitter, overruns);
            Console.WriteLine("pose age at read (now - HostTimeNs): p50 {0:F1} us, p90 {1:F1} us, p99 {2:F1} us, max {3:F1} us",
                              Percentile(ages, 50), Percentile(ages, 90), Percentile(ages, 99), ages[ages.Count - 1]);
            Console.WriteLine("poses: {0} new of {1} reads, {2} stale/disconnected, {3} errors; device: {4} reports, {5} dropped",
                              fresh, ages.Count, stale, errors, stats.Reports, pose.Dropped - first.Dropped);
            if (fresh == 0) { Console.Error.WriteLine("TeleopLoop: the device sent no new pose"); return 1; }
            return errors == 0 ? 0 : 1;
        }
    }
}
