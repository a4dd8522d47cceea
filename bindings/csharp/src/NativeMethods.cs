// P/Invoke declarations of include/cdm/cdm.h, and the native struct mirrors.
//
// How "cdm" becomes libcdm.so.1:
//  - Mono (and Unity's Mono): Cdm.dll.config, shipped beside Cdm.dll, maps it
//    (<dllmap dll="cdm" target="libcdm.so.1"/>); the dynamic linker then finds
//    libcdm.so.1 on its usual path (ldconfig cache, LD_LIBRARY_PATH).
//  - .NET (Core) ignores dllmap: it probes libcdm.so, which only the -dev
//    symlink provides. Either put that symlink (or the library) beside the app
//    or on LD_LIBRARY_PATH, or register a resolver in the app (NativeLibrary is
//    not in netstandard2.0, so this assembly cannot do it itself):
//      NativeLibrary.SetDllImportResolver(typeof(Cdm.Device).Assembly,
//          (name, asm, path) => name == "cdm" ? NativeLibrary.Load("libcdm.so.1") : IntPtr.Zero);
// docs/bindings.md says the same.
using System;
using System.Runtime.InteropServices;

namespace Cdm
{
    /// <summary>Marks a native mirror with the C struct it mirrors (the layout test reads it).</summary>
    [AttributeUsage(AttributeTargets.Struct)]
    internal sealed class CStructAttribute : Attribute
    {
        public readonly string Name;
        public CStructAttribute(string name) { Name = name; }
    }

    // Arrays of the C structs are spelled out element by element (position_0..2)
    // where the struct is read at control-loop rates: the struct stays blittable
    // and a read allocates nothing (Unity's garbage collector thanks us).
    [CStruct("cdm_pose"), StructLayout(LayoutKind.Sequential)]
    internal struct NativePose
    {
        public uint struct_size;
        public uint flags;
        public double position_0, position_1, position_2;
        public double orientation_0, orientation_1, orientation_2, orientation_3;
        public double grip;
        public uint buttons;
        public uint sequence;
        public ulong device_time_us;
        public ulong host_time_ns;
        public uint dropped;
        public uint reserved0;
        public ulong host_sequence; // since 1.1
        public double velocity_0, velocity_1, velocity_2; // since 1.1
    }

    [CStruct("cdm_raw"), StructLayout(LayoutKind.Sequential)]
    internal struct NativeRaw
    {
        public uint struct_size;
        public uint status;
        public ushort pot_adc_0, pot_adc_1, pot_adc_2, pot_adc_3;
        public ushort hall_adc;
        public ushort buttons;
        public short quat_q14_0, quat_q14_1, quat_q14_2, quat_q14_3;
        public uint sequence;
        public double lengths_mm_0, lengths_mm_1, lengths_mm_2, lengths_mm_3;
        public ulong device_time_us;
        public ulong host_time_ns;
    }

    [CStruct("cdm_device_info"), StructLayout(LayoutKind.Sequential, CharSet = CharSet.Ansi)]
    internal struct NativeDeviceInfo
    {
        public uint struct_size;
        public ushort vendor_id;
        public ushort product_id;
        [MarshalAs(UnmanagedType.ByValTStr, SizeConst = 256)] public string uri;
        [MarshalAs(UnmanagedType.ByValTStr, SizeConst = 32)] public string serial;
        [MarshalAs(UnmanagedType.ByValTStr, SizeConst = 16)] public string firmware;
        [MarshalAs(UnmanagedType.ByValTStr, SizeConst = 16)] public string transport;
        public uint protocol_version;
        public uint adc_bits;
        [MarshalAs(UnmanagedType.ByValArray, SizeConst = 4)] public double[] pot_scale_mm;
        [MarshalAs(UnmanagedType.ByValArray, SizeConst = 4)] public double[] pot_offset_mm;
        public double a_mm, b_mm, m_mm;
        public double report_rate_hz;
        public double hall_closed;
        public double hall_open;
        public double grip_open_rad;
    }

    [CStruct("cdm_stats"), StructLayout(LayoutKind.Sequential)]
    internal struct NativeStats
    {
        public uint struct_size;
        public uint reserved0;
        public ulong reports;
        public ulong malformed;
        public ulong dropped;
        public ulong out_of_workspace;
        public ulong reconnects;
        public ulong sequence_jumps; // since 1.1
        public ulong out_of_order; // since 1.1
        public ulong replay_truncated_bytes; // since 1.1
        public ulong restarts; // since 1.2
    }

    [CStruct("cdm_sample"), StructLayout(LayoutKind.Sequential)]
    internal struct NativeSample
    {
        public uint struct_size;
        public uint report_len;
        public IntPtr report;
        public IntPtr raw;
        public IntPtr pose;
        public ulong source_time_ns; // since 1.1
    }

    [CStruct("cdm_open_options"), StructLayout(LayoutKind.Sequential)]
    internal struct NativeOpenOptions
    {
        public uint struct_size;
        public uint stale_timeout_us;
        public IntPtr on_sample; // Marshal.GetFunctionPointerForDelegate(SampleFn), kept alive by DeviceHandle
        public IntPtr user;
        public IntPtr on_event;  // since 1.1: EventFn, kept alive by DeviceHandle
        public IntPtr on_rejected; // since 1.2: not set by this binding
    }

    [CStruct("cdm_rejected"), StructLayout(LayoutKind.Sequential)]
    internal struct NativeRejected
    {
        public uint struct_size;
        public uint kind;
        public IntPtr report;
        public uint report_len;
        public uint reserved0;
        public ulong source_time_ns;
        public IntPtr reason;
    }

    [CStruct("cdm_event"), StructLayout(LayoutKind.Sequential)]
    internal struct NativeEvent
    {
        public uint struct_size;
        public uint kind;
        public ulong host_time_ns;
        public IntPtr text;
    }

    /// <summary>cdm_effect_context (CDM_EXPERIMENTAL, since 1.2): what a geometry-aware effect sees.</summary>
    [CStruct("cdm_effect_context"), StructLayout(LayoutKind.Sequential)]
    internal struct NativeEffectContext
    {
        public uint struct_size;
        public uint stage;
        public UIntPtr n;
        public IntPtr positions_mm;
        public IntPtr t_s;
        public IntPtr anchors_mm;
        public IntPtr holders_mm;
        public IntPtr unit;
        public IntPtr chord_mm;
    }

    /// <summary>cdm_effect_def (CDM_EXPERIMENTAL): Cdm.Effects registers geometry-aware effects with it.</summary>
    [CStruct("cdm_effect_def"), StructLayout(LayoutKind.Sequential)]
    internal struct NativeEffectDef
    {
        public uint struct_size;
        public uint n_params;
        public IntPtr name;
        public IntPtr doc;
        public IntPtr param_names;
        public IntPtr param_scale;
        public IntPtr lower;
        public IntPtr upper;
        public IntPtr apply;
        public IntPtr user;
        public IntPtr initial; // since 1.1
        public IntPtr apply_batch; // since 1.1
        public IntPtr param_units; // since 1.2
        public IntPtr apply_geom; // since 1.2: Marshal.GetFunctionPointerForDelegate(EffectGeomFn), kept alive by Cdm.Effects
        public IntPtr origin; // since 1.2
        public uint stage; // since 1.2
    }

    /// <summary>cdm_watch_event (CDM_EXPERIMENTAL, since 1.1).</summary>
    [CStruct("cdm_watch_event"), StructLayout(LayoutKind.Sequential)]
    internal struct NativeWatchEvent
    {
        public uint struct_size;
        public uint kind;
        public ulong host_time_ns;
        public IntPtr info; // const cdm_device_info *
    }

    [UnmanagedFunctionPointer(CallingConvention.Cdecl)]
    internal delegate void SampleFn(IntPtr user, IntPtr sample);

    [UnmanagedFunctionPointer(CallingConvention.Cdecl)]
    internal delegate void WatchFn(IntPtr user, IntPtr ev);

    [UnmanagedFunctionPointer(CallingConvention.Cdecl)]
    internal delegate void EventFn(IntPtr user, IntPtr ev);

    [UnmanagedFunctionPointer(CallingConvention.Cdecl)]
    internal delegate void LogFn(IntPtr user, int level, IntPtr message);

    [UnmanagedFunctionPointer(CallingConvention.Cdecl)]
    internal delegate int EffectGeomFn(IntPtr user, IntPtr parameters, UIntPtr n, IntPtr ctx, IntPtr values);

    internal static class NativeMethods
    {
        private const string Lib = "cdm";

        // Text the library owns (static, or valid until the thread's next call):
        // returned as IntPtr so that the marshaller does not try to free it.
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern IntPtr cdm_version();
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_version_number();
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern IntPtr cdm_strerror(int code);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern IntPtr cdm_thread_error();

        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_enumerate(out DeviceListHandle list);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern UIntPtr cdm_device_list_count(DeviceListHandle list);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_device_list_get(DeviceListHandle list, UIntPtr i, ref NativeDeviceInfo info);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern void cdm_device_list_free(IntPtr list);

        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl, CharSet = CharSet.Ansi, BestFitMapping = false)]
        internal static extern int cdm_open(string uri, out DeviceHandle dev);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl, CharSet = CharSet.Ansi, BestFitMapping = false)]
        internal static extern int cdm_open_ex(string uri, ref NativeOpenOptions options, out DeviceHandle dev);

        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)]
        internal static extern void cdm_set_log_fn(LogFn fn, IntPtr user);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern void cdm_close(IntPtr dev);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_shutdown(DeviceHandle dev);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_get_pose(DeviceHandle dev, ref NativePose pose);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_wait_pose(DeviceHandle dev, int timeoutMs, ref NativePose pose);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_wait_pose_after(DeviceHandle dev, ulong afterHostSequence, int timeoutMs, ref NativePose pose);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_get_raw(DeviceHandle dev, ref NativeRaw raw);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_get_info(DeviceHandle dev, ref NativeDeviceInfo info);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_set_stale_timeout(DeviceHandle dev, uint timeoutUs);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_get_stats(DeviceHandle dev, ref NativeStats stats);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_device_error(DeviceHandle dev, byte[] buf, UIntPtr len);

        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl, CharSet = CharSet.Ansi, BestFitMapping = false)]
        internal static extern int cdm_calibration_load(string path, out CalibrationHandle cal);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_calibration_parse(byte[] json, UIntPtr len, out CalibrationHandle cal);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern void cdm_calibration_free(IntPtr cal);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_calibration_position(CalibrationHandle cal, double[] lengthsMm, [Out] double[] positionMm);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_calibration_lengths(CalibrationHandle cal, double[] positionMm, [Out] double[] lengthsMm);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern UIntPtr cdm_calibration_effect_count(CalibrationHandle cal);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern IntPtr cdm_calibration_effect_name(CalibrationHandle cal, UIntPtr i);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_set_calibration(DeviceHandle dev, CalibrationHandle cal);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl, EntryPoint = "cdm_set_calibration")]
        internal static extern int cdm_set_calibration_nominal(DeviceHandle dev, IntPtr nullCal);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_device_calibration_read(DeviceHandle dev, [Out] byte[] buf, UIntPtr cap, out UIntPtr len);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_device_calibration_write(DeviceHandle dev, byte[] data, UIntPtr len);

        // CDM_EXPERIMENTAL: user effects
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_effect_register(ref NativeEffectDef def);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_effect_unregister(byte[] name);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_effect_load_plugin(byte[] path);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern UIntPtr cdm_effect_count();
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern IntPtr cdm_effect_name(UIntPtr i);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_effect_fingerprint(UIntPtr i, [Out] byte[] buf, UIntPtr len, out IntPtr origin);

        // CDM_EXPERIMENTAL: hot-plug (since 1.1)
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern int cdm_watch(uint flags, WatchFn fn, IntPtr user, out WatcherHandle watcher);
        [DllImport(Lib, CallingConvention = CallingConvention.Cdecl)] internal static extern void cdm_watch_free(IntPtr watcher);

        /// <summary>UTF-8 text at p (NULL gives "").</summary>
        internal static string Utf8(IntPtr p)
        {
            if (p == IntPtr.Zero) return "";
            int n = 0;
            while (Marshal.ReadByte(p, n) != 0) n++;
            var bytes = new byte[n];
            Marshal.Copy(p, bytes, 0, n);
            return System.Text.Encoding.UTF8.GetString(bytes);
        }
    }
}
