// One SafeHandle per opaque C type: the runtime frees the native object even
// when the owner forgets Dispose, and never while a P/Invoke call uses it.
using System;
using System.Runtime.InteropServices;

namespace Cdm
{
    internal sealed class DeviceHandle : SafeHandle
    {
        // The sample delegate handed to cdm_open_ex: native code calls it from
        // the reader thread until cdm_close returns (or, for a close from the
        // callback itself, until that callback has returned), so they are
        // never dropped here: they live as long as this handle object.
        internal SampleFn SampleCallback;
        internal EventFn EventCallback;

        public DeviceHandle() : base(IntPtr.Zero, true) { }
        public override bool IsInvalid { get { return handle == IntPtr.Zero; } }

        // Runs when the last call using the handle has returned. On another
        // thread cdm_close joins the reader thread; on the reader thread (a
        // Dispose from the device's own callback) libcdm defers the close
        // until the callback returns.
        protected override bool ReleaseHandle()
        {
            NativeMethods.cdm_close(handle);
            return true;
        }
    }

    internal sealed class CalibrationHandle : SafeHandle
    {
        public CalibrationHandle() : base(IntPtr.Zero, true) { }
        public override bool IsInvalid { get { return handle == IntPtr.Zero; } }

        protected override bool ReleaseHandle()
        {
            NativeMethods.cdm_calibration_free(handle);
            return true;
        }
    }

    internal sealed class DeviceListHandle : SafeHandle
    {
        public DeviceListHandle() : base(IntPtr.Zero, true) { }
        public override bool IsInvalid { get { return handle == IntPtr.Zero; } }

        protected override bool ReleaseHandle()
        {
            NativeMethods.cdm_device_list_free(handle);
            return true;
        }
    }

    internal sealed class WatcherHandle : SafeHandle
    {
        // The delegate handed to cdm_watch: the watcher's thread calls it
        // until cdm_watch_free returns, so it lives exactly as long as this handle.
        internal WatchFn Callback;

        public WatcherHandle() : base(IntPtr.Zero, true) { }
        public override bool IsInvalid { get { return handle == IntPtr.Zero; } }

        protected override bool ReleaseHandle()
        {
            NativeMethods.cdm_watch_free(handle); // joins the watcher's thread: no callback after this
            Callback = null;
            return true;
        }
    }
}
