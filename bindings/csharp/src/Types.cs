using System;
using System.Runtime.InteropServices;

namespace Cdm
{
    /// <summary>since 1.1: cdm_event_kind.</summary>
    public enum DeviceEvent : uint
    {
        Disconnected = 1,
        Reconnected = 2,
        Stale = 3,
        Fresh = 4,
        EndOfStream = 5
    }

    /// <summary>since 1.1: libcdm's messages (cdm_set_log_fn) as a .NET event.</summary>
    public static class Log
    {
        static readonly object Gate = new object();
        static LogFn hook; // kept alive while installed
        static Action<int, string> handlers;

        /// <summary>Raised with (level 0 debug .. 3 error, message) from libcdm's threads.</summary>
        public static event Action<int, string> Message
        {
            add
            {
                lock (Gate)
                {
                    handlers += value;
                    if (hook == null)
                    {
                        hook = (user, level, msg) =>
                        {
                            var h = handlers;
                            if (h != null) h(level, Marshal.PtrToStringAnsi(msg) ?? "");
                        };
                        NativeMethods.cdm_set_log_fn(hook, IntPtr.Zero);
                    }
                }
            }
            remove
            {
                lock (Gate)
                {
                    handlers -= value;
                    if (handlers == null && hook != null)
                    {
                        NativeMethods.cdm_set_log_fn(null, IntPtr.Zero);
                        hook = null;
                    }
                }
            }
        }
    }

    /// <summary>A position in mm (device frame: x out of the cable plane, y-z the plane).</summary>
    public struct Vector3d
    {
        public double X, Y, Z;
        public Vector3d(double x, double y, double z) { X = x; Y = y; Z = z; }
        public double this[int i]
        {
            get
            {
                switch (i) { case 0: return X; case 1: return Y; case 2: return Z; }
                throw new IndexOutOfRangeException("Vector3d index " + i + " is not 0..2");
            }
        }
        public double[] ToArray() { return new[] { X, Y, Z }; }
        public override string ToString() { return string.Format("({0:F3}, {1:F3}, {2:F3})", X, Y, Z); }
    }

    /// <summary>A unit quaternion w, x, y, z (the grip's IMU orientation).</summary>
    public struct Quaterniond
    {
        public double W, X, Y, Z;
        public Quaterniond(double w, double x, double y, double z) { W = w; X = x; Y = y; Z = z; }
        public double Norm { get { return Math.Sqrt(W * W + X * X + Y * Y + Z * Z); } }
        public override string ToString() { return string.Format("({0:F4}, {1:F4}, {2:F4}, {3:F4})", W, X, Y, Z); }
    }

    /// <summary>cdm_pose as managed values. Status is what the call returned:
    /// Ok, or Stale / Disconnected / EndOfStream for the last pose, held.</summary>
    public struct Pose
    {
        public Vector3d Position;
        public Quaterniond Orientation;
        /// <summary>Jaw opening, rad (0 = closed).</summary>
        public double Grip;
        public Buttons Buttons;
        public uint Sequence;
        public uint Dropped;
        public PoseFlags Flags;
        public ulong DeviceTimeUs;
        /// <summary>CLOCK_MONOTONIC (ns) when the report was received.</summary>
        public ulong HostTimeNs;
        /// <summary>since 1.1: poses this handle has published so far (host side,
        /// monotonic); pass it to Device.WaitPoseAfter.</summary>
        public ulong HostSequence;
        /// <summary>since 1.1: holder velocity, mm/s, device frame (a low-passed
        /// difference: 50 Hz, about 3.7 ms of lag; docs/protocol.md).</summary>
        public Vector3d Velocity;
        public ErrorCode Status;

        public bool IsStale { get { return (Flags & PoseFlags.Stale) != 0; } }
        public bool IsDisconnected { get { return (Flags & PoseFlags.Disconnected) != 0; } }
        public bool IsCompensated { get { return (Flags & PoseFlags.Compensated) != 0; } }
        public bool IsOutOfWorkspace { get { return (Flags & PoseFlags.OutOfWorkspace) != 0; } }
        public bool IsEndOfStream { get { return (Flags & PoseFlags.EndOfStream) != 0 || Status == ErrorCode.EndOfStream; } }
        public bool Clutch { get { return (Buttons & Buttons.Clutch) != 0; } }

        internal static Pose From(ref NativePose p, int status)
        {
            Pose r;
            r.Position = new Vector3d(p.position_0, p.position_1, p.position_2);
            r.Orientation = new Quaterniond(p.orientation_0, p.orientation_1, p.orientation_2, p.orientation_3);
            r.Grip = p.grip;
            r.Buttons = (Buttons)p.buttons;
            r.Sequence = p.sequence;
            r.Dropped = p.dropped;
            r.Flags = (PoseFlags)p.flags;
            r.DeviceTimeUs = p.device_time_us;
            r.HostTimeNs = p.host_time_ns;
            r.HostSequence = p.host_sequence;
            r.Velocity = new Vector3d(p.velocity_0, p.velocity_1, p.velocity_2);
            r.Status = (ErrorCode)status;
            return r;
        }

        public override string ToString()
        {
            return string.Format("#{0} pos {1} mm q {2} grip {3:F3} rad buttons {4} flags {5}",
                                 Sequence, Position, Orientation, Grip, Buttons, Flags);
        }
    }

    /// <summary>cdm_raw: the newest report's sensor values.</summary>
    public struct Raw
    {
        public uint Status;
        public ushort[] PotAdc;
        public ushort HallAdc;
        public ushort Buttons;
        public short[] QuatQ14;
        public uint Sequence;
        public double[] LengthsMm;
        public ulong DeviceTimeUs;
        public ulong HostTimeNs;

        internal static Raw From(ref NativeRaw r)
        {
            Raw o;
            o.Status = r.status;
            o.PotAdc = new[] { r.pot_adc_0, r.pot_adc_1, r.pot_adc_2, r.pot_adc_3 };
            o.HallAdc = r.hall_adc;
            o.Buttons = r.buttons;
            o.QuatQ14 = new[] { r.quat_q14_0, r.quat_q14_1, r.quat_q14_2, r.quat_q14_3 };
            o.Sequence = r.sequence;
            o.LengthsMm = new[] { r.lengths_mm_0, r.lengths_mm_1, r.lengths_mm_2, r.lengths_mm_3 };
            o.DeviceTimeUs = r.device_time_us;
            o.HostTimeNs = r.host_time_ns;
            return o;
        }
    }

    /// <summary>cdm_device_info: what a device says about itself.</summary>
    public sealed class DeviceInfo
    {
        public ushort VendorId, ProductId;
        public string Uri, Serial, Firmware, Transport;
        public uint ProtocolVersion, AdcBits;
        public double[] PotScaleMm, PotOffsetMm;
        public double AMm, BMm, MMm;
        public double ReportRateHz;
        public double HallClosed, HallOpen, GripOpenRad;

        internal static DeviceInfo From(ref NativeDeviceInfo i)
        {
            return new DeviceInfo
            {
                VendorId = i.vendor_id, ProductId = i.product_id,
                Uri = i.uri ?? "", Serial = i.serial ?? "", Firmware = i.firmware ?? "", Transport = i.transport ?? "",
                ProtocolVersion = i.protocol_version, AdcBits = i.adc_bits,
                PotScaleMm = (double[])i.pot_scale_mm.Clone(), PotOffsetMm = (double[])i.pot_offset_mm.Clone(),
                AMm = i.a_mm, BMm = i.b_mm, MMm = i.m_mm, ReportRateHz = i.report_rate_hz,
                HallClosed = i.hall_closed, HallOpen = i.hall_open, GripOpenRad = i.grip_open_rad,
            };
        }

        internal static NativeDeviceInfo Empty()
        {
            var n = new NativeDeviceInfo
            {
                pot_scale_mm = new double[4],
                pot_offset_mm = new double[4],
            };
            n.struct_size = (uint)System.Runtime.InteropServices.Marshal.SizeOf(typeof(NativeDeviceInfo));
            return n;
        }
    }

    /// <summary>cdm_stats: counters of the reader thread.</summary>
    public struct Stats
    {
        public ulong Reports, Malformed, Dropped, OutOfWorkspace, Reconnects;
        /// <summary>since 1.1: sequence-counter resets or corruptions (not in Dropped);
        /// duplicated or late reports discarded; bytes of a truncated recording's tail.</summary>
        public ulong SequenceJumps, OutOfOrder, ReplayTruncatedBytes;
        /// <summary>since 1.2: the device restarted its counter (a firmware restart), not in SequenceJumps.</summary>
        public ulong Restarts;
    }
}
