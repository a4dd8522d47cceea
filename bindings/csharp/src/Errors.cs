using System;

namespace Cdm
{
    /// <summary>cdm_error: the library's return codes (values pinned by the C ABI).</summary>
    public enum ErrorCode
    {
        Ok = 0,
        InvalidArg = -1,
        NoDevice = -2,
        IO = -3,
        Timeout = -4,
        Disconnected = -5,
        Stale = -6,
        NoData = -7,
        Protocol = -8,
        Unsupported = -9,
        NoMem = -10,
        Parse = -11,
        Numeric = -12,
        EndOfStream = -13,
        Crc = -14,
        Internal = -15,
        /// <summary>since 1.2: a wait ended by Dispose (cdm_close / cdm_shutdown): no pose.</summary>
        Closed = -16,
    }

    /// <summary>cdm_pose_flag bits.</summary>
    [Flags]
    public enum PoseFlags : uint
    {
        None = 0,
        Stale = 1u << 0,
        Disconnected = 1u << 1,
        Compensated = 1u << 2,
        OutOfWorkspace = 1u << 3,
        EndOfStream = 1u << 4,
        /// <summary>since 1.1: no position was ever computed; Position is meaningless.</summary>
        NoPosition = 1u << 5,
    }

    /// <summary>cdm_button bits.</summary>
    [Flags]
    public enum Buttons : uint
    {
        None = 0,
        Clutch = 1u << 0,
        Aux = 1u << 1,
        Mark = 1u << 2,
    }

    /// <summary>A libcdm call failed. Message: cdm_strerror text, then the library's detail (what and where).</summary>
    public class CdmException : Exception
    {
        public ErrorCode Code { get; private set; }
        /// <summary>The library's detail text alone ("" when it gave none).</summary>
        public string Detail { get; private set; }
        /// <summary>The C function that failed, e.g. "cdm_open".</summary>
        public string Function { get; private set; }

        public CdmException(ErrorCode code, string function, string detail)
            : base(Compose(code, function, detail))
        {
            Code = code;
            Function = function;
            Detail = detail ?? "";
        }

        static string Compose(ErrorCode code, string function, string detail)
        {
            string text;
            try { text = NativeMethods.Utf8(NativeMethods.cdm_strerror((int)code)); }
            catch (Exception) { text = code.ToString(); } // the library itself could not be loaded
            var s = (function != null ? function + ": " : "") + text;
            if (!string.IsNullOrEmpty(detail)) s += ": " + detail;
            return s + " (" + code + ")";
        }
    }

    internal static class Check
    {
        /// <summary>The one place a return code becomes an exception. Call it
        /// right after the call: the thread's detail text is only valid until
        /// its next cdm_* call.</summary>
        internal static int Ensure(int code, string function, DeviceHandle dev = null)
        {
            if (code >= 0) return code;
            throw Error(code, function, dev);
        }

        internal static CdmException Error(int code, string function, DeviceHandle dev = null)
        {
            var detail = NativeMethods.Utf8(NativeMethods.cdm_thread_error());
            if (detail.Length == 0 && dev != null && !dev.IsClosed && !dev.IsInvalid)
                detail = Device.ErrorText(dev);
            return new CdmException((ErrorCode)code, function, detail);
        }
    }
}
