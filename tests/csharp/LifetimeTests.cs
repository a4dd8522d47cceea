// Cdm.Device lifetimes against re-entrancy (docs/reliability.md,
// "Callbacks"): Dispose from the device's own callbacks and from the log
// sink, Dispose while another thread waits, what a callback may call. Part
// of CdmTests.exe (group "device").
using System;
using System.Threading;
using Cdm;

static partial class CdmTests
{
    // ---------------------------------------------------------- lifetimes
    // (docs/reliability.md, "Callbacks": one test per row.)

    // Dispose while another thread is in WaitPoseAfter(..., -1) on a stalled
    // device: the waiter throws ErrorCode.Closed (it hung forever: the
    // SafeHandle postponed the close until the call returned, and nothing
    // woke the call). The joins are bounded so that a hang fails the check.
    static void DisposeWakesBlockedWaiter()
    {
        var dev = Device.Open("sim:?rate=1000&stall_after=10");
        var first = dev.WaitPose(2000);
        Thread.Sleep(100); // the device is silent from here on
        var last = dev.GetPose();
        ErrorCode got = ErrorCode.Ok;
        bool gotPose = false;
        var t = new Thread(() =>
        {
            try { dev.WaitPoseAfter(last.HostSequence, -1); gotPose = true; }
            catch (CdmException e) { got = e.Code; }
            catch (ObjectDisposedException) { got = ErrorCode.InvalidArg; }
        });
        t.Start();
        Thread.Sleep(100);
        var disposer = new Thread(() => dev.Dispose());
        disposer.Start();
        Expect(disposer.Join(5000), "Dispose returned within 5 s with a blocked waiter");
        Expect(t.Join(5000), "the blocked waiter returned within 5 s of Dispose");
        Expect(!gotPose && got == ErrorCode.Closed, "waiter: " + (gotPose ? "a pose" : got.ToString()) + ", want Closed");
        Expect(dev.IsDisposed && first.HostSequence > 0, "disposed");
    }

    static void DisposeInsideSampleCallback()
    {
        Device dev = null;
        int disposed = 0, after = 0;
        Exception error = null;
        dev = Device.Open("sim:?rate=1000", 0, p =>
        {
            var d = dev;
            if (d == null) return;
            if (Volatile.Read(ref disposed) != 0) { Interlocked.Increment(ref after); return; }
            try { d.Dispose(); } catch (Exception e) { error = e; }
            Volatile.Write(ref disposed, 1);
        });
        var until = DateTime.UtcNow.AddSeconds(3);
        while (Volatile.Read(ref disposed) == 0 && DateTime.UtcNow < until) Thread.Sleep(5);
        Thread.Sleep(100);
        Expect(Volatile.Read(ref disposed) == 1, "the callback disposed its device");
        Expect(error == null, "Dispose in on-sample threw " + error);
        Expect(dev.IsDisposed, "IsDisposed after Dispose in the callback");
        Expect(Volatile.Read(ref after) == 0, after + " callbacks after the Dispose");
        try { dev.GetPose(); Expect(false, "GetPose after Dispose did not throw"); }
        catch (ObjectDisposedException) { }
    }

    static void DisposeInsideEventCallback()
    {
        Device dev = null;
        int disposed = 0;
        Exception error = null;
        dev = Device.Open("sim:?rate=1000&stall_after=20", 0, null, (kind, text) =>
        {
            var d = dev;
            if (d == null || kind != DeviceEvent.Stale) return;
            try { d.Dispose(); } catch (Exception e) { error = e; }
            Volatile.Write(ref disposed, 1);
        });
        var until = DateTime.UtcNow.AddSeconds(3);
        while (Volatile.Read(ref disposed) == 0 && DateTime.UtcNow < until) Thread.Sleep(5);
        Expect(Volatile.Read(ref disposed) == 1, "the event callback disposed its device");
        Expect(error == null, "Dispose in on-event threw " + error);
        Expect(dev.IsDisposed, "IsDisposed after Dispose in the event callback");
    }

    // The log sink (on the reader thread: a rejected report's warning)
    // disposes the device.
    static void DisposeInsideLogSink()
    {
        Device dev = null;
        int disposed = 0;
        Exception error = null;
        Action<int, string> h = (level, msg) =>
        {
            var d = dev;
            if (d == null || !msg.Contains("rejected") || Interlocked.Exchange(ref disposed, 1) != 0) return;
            try { d.Dispose(); } catch (Exception e) { error = e; }
        };
        Log.Message += h;
        try
        {
            dev = Device.Open("sim:?rate=1000&malformed=short:50");
            var until = DateTime.UtcNow.AddSeconds(3);
            while (Volatile.Read(ref disposed) == 0 && DateTime.UtcNow < until) Thread.Sleep(5);
            Thread.Sleep(50);
        }
        finally { Log.Message -= h; }
        Expect(Volatile.Read(ref disposed) == 1, "the log sink disposed the device");
        Expect(error == null, "Dispose in the log sink threw " + error);
        Expect(dev.IsDisposed, "IsDisposed after Dispose in the log sink");
    }

    // WaitPose on its own device from the sample callback: InvalidArg at once
    // (no pose can arrive while the reader thread waits).
    static void WaitInsideOwnCallbackRefused()
    {
        Device dev = null;
        int done = 0;
        ErrorCode got = ErrorCode.Ok;
        double ms = -1;
        dev = Device.Open("sim:?rate=200", 0, p =>
        {
            var d = dev;
            if (d == null || Volatile.Read(ref done) != 0) return;
            var t0 = DateTime.UtcNow;
            try { d.WaitPose(5000); }
            catch (CdmException e) { got = e.Code; }
            ms = (DateTime.UtcNow - t0).TotalMilliseconds;
            Volatile.Write(ref done, 1);
        });
        var until = DateTime.UtcNow.AddSeconds(3);
        while (Volatile.Read(ref done) == 0 && DateTime.UtcNow < until) Thread.Sleep(5);
        dev.Dispose();
        Expect(got == ErrorCode.InvalidArg, "WaitPose in the callback: " + got + ", want InvalidArg");
        Expect(ms >= 0 && ms < 1000, "refused at once, not after the 5 s wait: " + ms + " ms");
    }

    // Every non-blocking call on its own device works from the callback.
    static void CallbackMayCallItsDevice()
    {
        Device dev = null;
        int done = 0;
        Exception error = null;
        dev = Device.Open("sim:?rate=1000", 0, p =>
        {
            var d = dev;
            if (d == null || Volatile.Read(ref done) != 0) return;
            try
            {
                d.GetPose();
                d.GetRaw();
                d.GetInfo();
                d.GetStats();
                var unused = d.LastError;
                d.SetStaleTimeout(0);
                d.SetCalibration(null);
            }
            catch (Exception e) { error = e; }
            Volatile.Write(ref done, 1);
        });
        var until = DateTime.UtcNow.AddSeconds(3);
        while (Volatile.Read(ref done) == 0 && DateTime.UtcNow < until) Thread.Sleep(5);
        dev.Dispose();
        Expect(Volatile.Read(ref done) == 1, "the callback ran");
        Expect(error == null, "a call from the callback threw " + error);
    }
}
