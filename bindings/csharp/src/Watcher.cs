using System;
using System.Runtime.InteropServices;
using System.Threading;

namespace Cdm
{
    /// <summary>Experimental, since 1.1: cdm_watch_kind.</summary>
    public enum WatchEvent : uint
    {
        Arrived = 1,
        Left = 2
    }

    /// <summary>Experimental, since 1.1 (cdm_watch): arrivals and departures of masters as
    /// they happen, from udev's hot-plug events (docs/reliability.md, "Hot-plug").
    /// The callback runs on the watcher's own thread, one event at a time. Dispose (a
    /// using-block) stops it: when Dispose returns the callback is not running and will
    /// not run again. Dispose from inside the callback throws InvalidOperationException
    /// (it would join the thread it runs on).</summary>
    public sealed class Watcher : IDisposable
    {
        [ThreadStatic] static Watcher _inCallback;
        readonly WatcherHandle _h;

        Watcher(WatcherHandle h) { _h = h; }

        /// <summary>Calls <paramref name="onChange"/>(kind, info) for every master that
        /// arrives or leaves (for Left, info is what was known when it arrived). With
        /// <paramref name="enumerate"/>, the masters already connected come first as Arrived.</summary>
        public static Watcher Start(Action<WatchEvent, DeviceInfo> onChange, bool enumerate)
        {
            if (onChange == null) throw new ArgumentNullException("onChange");
            NativeLoad.EnsureLoaded();
            Watcher self = null;
            var started = new ManualResetEvent(false);
            WatchFn fn = (user, ev) =>
            {
                // The first events (CDM_WATCH_ENUMERATE) may come before cdm_watch has
                // returned the handle: wait for it, so that _inCallback names this watcher.
                started.WaitOne();
                var e = (NativeWatchEvent)Marshal.PtrToStructure(ev, typeof(NativeWatchEvent));
                var ni = (NativeDeviceInfo)Marshal.PtrToStructure(e.info, typeof(NativeDeviceInfo));
                _inCallback = self;
                try { onChange((WatchEvent)e.kind, DeviceInfo.From(ref ni)); }
                catch (Exception x) { Console.Error.WriteLine("Cdm.Watcher callback: " + x); }
                finally { _inCallback = null; }
            };
            WatcherHandle h;
            int rc = NativeMethods.cdm_watch(enumerate ? 1u : 0u, fn, IntPtr.Zero, out h);
            if (rc < 0)
            {
                var err = Check.Error(rc, "cdm_watch");
                h.Dispose();
                started.Set();
                throw err;
            }
            h.Callback = fn; // lives as long as the handle: cdm_watch_free is the last point it can be called
            self = new Watcher(h);
            started.Set();
            GC.KeepAlive(fn);
            return self;
        }

        public bool IsDisposed { get { return _h.IsClosed; } }

        public void Dispose()
        {
            if (ReferenceEquals(_inCallback, this))
                throw new InvalidOperationException("Cdm.Watcher.Dispose from its own callback: it would join the thread it runs on");
            _h.Dispose();
        }
    }
}
