using System;
using System.Runtime.InteropServices;
using System.Text;

namespace Cdm
{
    /// <summary>An open master. Dispose it (using-block) to stop its reader thread.
    /// Every method may be called from any thread, Dispose included, and from the
    /// device's own callbacks. Dispose wakes the threads blocked in WaitPose /
    /// WaitPoseAfter (they throw CdmException with ErrorCode.Closed, never return a
    /// pose); the native handle is freed once the last call using it has returned
    /// (SafeHandle), and a Dispose from the device's own callback frees it when that
    /// callback returns (docs/reliability.md, "Callbacks").</summary>
    public sealed class Device : IDisposable
    {
        static readonly uint PoseSize = (uint)Marshal.SizeOf(typeof(NativePose));
        static readonly uint RawSize = (uint)Marshal.SizeOf(typeof(NativeRaw));
        static readonly uint StatsSize = (uint)Marshal.SizeOf(typeof(NativeStats));

        readonly DeviceHandle _h;
        public string Uri { get; private set; }

        Device(DeviceHandle h, string uri) { _h = h; Uri = uri; }

        /// <summary>"1.2.0": the version of the libcdm actually loaded.</summary>
        public static string LibraryVersion { get { NativeLoad.EnsureLoaded(); return NativeMethods.Utf8(NativeMethods.cdm_version()); } }
        /// <summary>CDM_VERSION_NUMBER of the libcdm actually loaded.</summary>
        public static int LibraryVersionNumber { get { NativeLoad.EnsureLoaded(); return NativeMethods.cdm_version_number(); } }

        /// <summary>Opens a master: null or "" ($CDM_DEVICE, else the first device),
        /// "sim:?...", "replay:FILE", "hid:/dev/hidrawN", "serial:SN".</summary>
        public static Device Open(string uri)
        {
            return Open(uri, 0, null);
        }

        /// <summary>Opens a master with a stale deadline (0: 50 ms) and an optional
        /// callback run on the reader thread for every report (it must return quickly).</summary>
        public static Device Open(string uri, uint staleTimeoutUs, Action<Pose> onSample)
        {
            return Open(uri, staleTimeoutUs, onSample, null);
        }

        /// <summary>since 1.1: as above, plus <paramref name="onEvent"/>(kind, text) on the reader
        /// thread when the device's state changes (disconnected, reconnected, stale, fresh,
        /// end of stream; cdm_event_kind).</summary>
        public static Device Open(string uri, uint staleTimeoutUs, Action<Pose> onSample, Action<DeviceEvent, string> onEvent)
        {
            NativeLoad.EnsureLoaded();
            var opts = new NativeOpenOptions();
            opts.struct_size = (uint)Marshal.SizeOf(typeof(NativeOpenOptions));
            opts.stale_timeout_us = staleTimeoutUs;
            SampleFn fn = null;
            if (onSample != null)
            {
                fn = (user, sample) =>
                {
                    var s = (NativeSample)Marshal.PtrToStructure(sample, typeof(NativeSample));
                    if (s.pose == IntPtr.Zero) return;
                    var p = (NativePose)Marshal.PtrToStructure(s.pose, typeof(NativePose));
                    try { onSample(Pose.From(ref p, 0)); }
                    catch (Exception e) { Console.Error.WriteLine("Cdm.Device on-sample callback: " + e); }
                    GC.KeepAlive(fn); // alive until the native caller is back, even after a Dispose in onSample
                };
                opts.on_sample = Marshal.GetFunctionPointerForDelegate(fn);
            }
            EventFn efn = null;
            if (onEvent != null)
            {
                efn = (user, ev) =>
                {
                    var e = (NativeEvent)Marshal.PtrToStructure(ev, typeof(NativeEvent));
                    try { onEvent((DeviceEvent)e.kind, Marshal.PtrToStringAnsi(e.text) ?? ""); }
                    catch (Exception x) { Console.Error.WriteLine("Cdm.Device event callback: " + x); }
                    GC.KeepAlive(efn);
                };
                opts.on_event = Marshal.GetFunctionPointerForDelegate(efn);
            }
            DeviceHandle h;
            int rc = NativeMethods.cdm_open_ex(uri, ref opts, out h);
            if (rc < 0)
            {
                var e = Check.Error(rc, "cdm_open");
                h.Dispose();
                throw e;
            }
            h.SampleCallback = fn; // lives as long as the handle: cdm_close is the last point it can be called
            h.EventCallback = efn;
            GC.KeepAlive(fn);
            GC.KeepAlive(efn);
            return new Device(h, uri);
        }

        /// <summary>Information about every connected master (an empty array is not an error).</summary>
        public static DeviceInfo[] Enumerate()
        {
            NativeLoad.EnsureLoaded();
            DeviceListHandle list;
            Check.Ensure(NativeMethods.cdm_enumerate(out list), "cdm_enumerate");
            using (list)
            {
                int n = (int)NativeMethods.cdm_device_list_count(list).ToUInt64();
                var r = new DeviceInfo[n];
                for (int i = 0; i < n; i++)
                {
                    var info = DeviceInfo.Empty();
                    Check.Ensure(NativeMethods.cdm_device_list_get(list, new UIntPtr((uint)i), ref info), "cdm_device_list_get");
                    r[i] = DeviceInfo.From(ref info);
                }
                return r;
            }
        }

        public bool IsDisposed { get { return _h.IsClosed; } }

        public void Dispose()
        {
            if (_h.IsClosed) return;
            // cdm_shutdown first: a thread inside WaitPoseAfter(..., -1) holds a
            // reference to the handle, which postpones its release until that call
            // returns; the shutdown makes it return (ErrorCode.Closed) at once.
            try { NativeMethods.cdm_shutdown(_h); }
            catch (ObjectDisposedException) { return; } // a concurrent Dispose won
            _h.Dispose();
        }

        DeviceHandle H
        {
            get
            {
                if (_h.IsClosed) throw new ObjectDisposedException("Cdm.Device(" + Uri + ")");
                return _h;
            }
        }

        static bool Filled(int rc)
        {
            return rc == (int)ErrorCode.Stale || rc == (int)ErrorCode.Disconnected || rc == (int)ErrorCode.EndOfStream;
        }

        /// <summary>The newest pose, without blocking. Throws CdmException (NoData) before the
        /// first report; a stale, disconnected or ended stream returns the last pose with
        /// Status and Flags saying so.</summary>
        public Pose GetPose()
        {
            Pose p;
            int rc = GetPoseCode(out p);
            if (rc < 0 && !Filled(rc)) throw Check.Error(rc, "cdm_get_pose", _h);
            return p;
        }

        /// <summary>GetPose without exceptions, for control loops: true when pose holds a pose
        /// (current, or the last one for Stale/Disconnected/EndOfStream: see pose.Status);
        /// false before the first report (pose.Status NoData) or on an error (pose.Status).</summary>
        public bool TryGetPose(out Pose pose)
        {
            int rc = GetPoseCode(out pose);
            return rc >= 0 || Filled(rc);
        }

        int GetPoseCode(out Pose pose)
        {
            var n = new NativePose();
            n.struct_size = PoseSize;
            int rc = NativeMethods.cdm_get_pose(H, ref n);
            pose = Pose.From(ref n, rc);
            return rc;
        }

        /// <summary>Blocks until a newer pose arrives; timeoutMs &lt; 0 waits without limit.
        /// Throws CdmException (Timeout) when none came in time.</summary>
        public Pose WaitPose(int timeoutMs)
        {
            var n = new NativePose();
            n.struct_size = PoseSize;
            int rc = NativeMethods.cdm_wait_pose(H, timeoutMs, ref n);
            if (rc < 0 && !Filled(rc)) throw Check.Error(rc, "cdm_wait_pose", _h);
            return Pose.From(ref n, rc);
        }

        /// <summary>Waits for a pose whose HostSequence is greater than afterHostSequence;
        /// returns at once if one already exists (no lost wake-up between calls).
        /// timeoutMs &lt; 0 waits without limit. Throws CdmException (Timeout) when none
        /// came in time.</summary>
        public Pose WaitPoseAfter(ulong afterHostSequence, int timeoutMs)
        {
            var n = new NativePose();
            n.struct_size = PoseSize;
            int rc = NativeMethods.cdm_wait_pose_after(H, afterHostSequence, timeoutMs, ref n);
            if (rc < 0 && !Filled(rc)) throw Check.Error(rc, "cdm_wait_pose_after", _h);
            return Pose.From(ref n, rc);
        }

        public Raw GetRaw()
        {
            var n = new NativeRaw();
            n.struct_size = RawSize;
            int rc = NativeMethods.cdm_get_raw(H, ref n);
            if (rc < 0 && !Filled(rc)) throw Check.Error(rc, "cdm_get_raw", _h);
            return Raw.From(ref n);
        }

        public DeviceInfo GetInfo()
        {
            var n = DeviceInfo.Empty();
            Check.Ensure(NativeMethods.cdm_get_info(H, ref n), "cdm_get_info", _h);
            return DeviceInfo.From(ref n);
        }

        public Stats GetStats()
        {
            var n = new NativeStats();
            n.struct_size = StatsSize;
            Check.Ensure(NativeMethods.cdm_get_stats(H, ref n), "cdm_get_stats", _h);
            return new Stats
            {
                Reports = n.reports, Malformed = n.malformed, Dropped = n.dropped,
                OutOfWorkspace = n.out_of_workspace, Reconnects = n.reconnects,
                SequenceJumps = n.sequence_jumps, OutOfOrder = n.out_of_order,
                ReplayTruncatedBytes = n.replay_truncated_bytes, Restarts = n.restarts,
            };
        }

        /// <summary>Poses older than this are flagged stale; 0 restores the default (50 ms).</summary>
        public void SetStaleTimeout(uint timeoutUs)
        {
            Check.Ensure(NativeMethods.cdm_set_stale_timeout(H, timeoutUs), "cdm_set_stale_timeout", _h);
        }

        /// <summary>Applies a calibration from the next report on (the library copies it);
        /// null returns to the nominal model.</summary>
        public void SetCalibration(Calibration calibration)
        {
            int rc = calibration == null
                ? NativeMethods.cdm_set_calibration_nominal(H, IntPtr.Zero)
                : NativeMethods.cdm_set_calibration(H, calibration.Handle);
            Check.Ensure(rc, "cdm_set_calibration", _h);
        }

        /// <summary>The calibration bytes stored in the device (CdmException Crc when corrupt).</summary>
        public byte[] ReadStoredCalibration()
        {
            var buf = new byte[4096];
            for (int attempt = 0; attempt < 3; attempt++)
            {
                UIntPtr len;
                int rc = NativeMethods.cdm_device_calibration_read(H, buf, new UIntPtr((uint)buf.Length), out len);
                ulong n = len.ToUInt64();
                if (rc == (int)ErrorCode.NoMem && n > (ulong)buf.Length) { buf = new byte[n]; continue; }
                Check.Ensure(rc, "cdm_device_calibration_read", _h);
                var r = new byte[n];
                Array.Copy(buf, r, (long)n);
                return r;
            }
            throw new CdmException(ErrorCode.Internal, "cdm_device_calibration_read", "kept asking for a bigger buffer");
        }

        public void WriteStoredCalibration(byte[] data)
        {
            if (data == null) throw new ArgumentNullException("data");
            Check.Ensure(NativeMethods.cdm_device_calibration_write(H, data, new UIntPtr((uint)data.Length)),
                         "cdm_device_calibration_write", _h);
        }

        /// <summary>The device's last asynchronous problem (cdm_device_error), "" if none.</summary>
        public string LastError { get { return ErrorText(H); } }

        internal static string ErrorText(DeviceHandle h)
        {
            var buf = new byte[1024];
            if (NativeMethods.cdm_device_error(h, buf, new UIntPtr((uint)buf.Length)) < 0) return "";
            int n = Array.IndexOf(buf, (byte)0);
            return Encoding.UTF8.GetString(buf, 0, n < 0 ? buf.Length : n);
        }
    }
}
