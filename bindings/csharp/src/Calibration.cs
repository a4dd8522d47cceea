using System;
using System.Text;

namespace Cdm
{
    /// <summary>A fitted calibration (cdm_calibration): corrected forward kinematics.
    /// Read-only once loaded: safe to share between threads.</summary>
    public sealed class Calibration : IDisposable
    {
        internal readonly CalibrationHandle Handle;
        public string Source { get; private set; }

        Calibration(CalibrationHandle h, string source) { Handle = h; Source = source; }

        /// <summary>Loads a calibration JSON file; errors name the file, line and column.</summary>
        public static Calibration Load(string path)
        {
            if (path == null) throw new ArgumentNullException("path");
            NativeLoad.EnsureLoaded();
            CalibrationHandle h;
            int rc = NativeMethods.cdm_calibration_load(path, out h);
            if (rc < 0) { var e = Check.Error(rc, "cdm_calibration_load"); h.Dispose(); throw e; }
            return new Calibration(h, path);
        }

        /// <summary>The same from JSON text.</summary>
        public static Calibration Parse(string json)
        {
            if (json == null) throw new ArgumentNullException("json");
            NativeLoad.EnsureLoaded();
            var bytes = Encoding.UTF8.GetBytes(json);
            CalibrationHandle h;
            int rc = NativeMethods.cdm_calibration_parse(bytes, new UIntPtr((uint)bytes.Length), out h);
            if (rc < 0) { var e = Check.Error(rc, "cdm_calibration_parse"); h.Dispose(); throw e; }
            return new Calibration(h, "<text>");
        }

        public void Dispose() { Handle.Dispose(); }

        CalibrationHandle H
        {
            get
            {
                if (Handle.IsClosed) throw new ObjectDisposedException("Cdm.Calibration(" + Source + ")");
                return Handle;
            }
        }

        /// <summary>The holder position (mm) whose predicted readings best match the 4
        /// nominal-scale pot readings (mm). CdmException Numeric when there is no solution.</summary>
        public Vector3d Position(double[] lengthsMm)
        {
            if (lengthsMm == null || lengthsMm.Length != 4)
                throw new ArgumentException("Calibration.Position: lengthsMm must hold 4 values (mm), got " +
                                            (lengthsMm == null ? "null" : lengthsMm.Length.ToString()), "lengthsMm");
            var p = new double[3];
            Check.Ensure(NativeMethods.cdm_calibration_position(H, lengthsMm, p), "cdm_calibration_position");
            return new Vector3d(p[0], p[1], p[2]);
        }

        /// <summary>The 4 readings (mm) the calibrated model predicts at a position (mm).</summary>
        public double[] Lengths(Vector3d positionMm)
        {
            var l = new double[4];
            Check.Ensure(NativeMethods.cdm_calibration_lengths(H, positionMm.ToArray(), l), "cdm_calibration_lengths");
            return l;
        }

        /// <summary>Names of the physical effects in this calibration, in model order.</summary>
        public string[] Effects
        {
            get
            {
                var h = H;
                int n = (int)NativeMethods.cdm_calibration_effect_count(h).ToUInt64();
                var r = new string[n];
                for (int i = 0; i < n; i++)
                    r[i] = NativeMethods.Utf8(NativeMethods.cdm_calibration_effect_name(h, new UIntPtr((uint)i)));
                return r;
            }
        }
    }
}
