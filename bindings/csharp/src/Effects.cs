using System;
using System.Collections.Generic;
using System.Runtime.InteropServices;
using System.Text;
using System.Text.RegularExpressions;

namespace Cdm
{
    /// <summary>Where a user effect acts (cdm_effect_stage, experimental, since 1.2).</summary>
    public enum EffectStage
    {
        /// <summary>On the readings, after the pot's transfer (ripple, drift, electronics).</summary>
        Reading = 0,
        /// <summary>On the cable's length before the pot's transfer (sag, guides, pulleys):
        /// cable_gain and the other transfer effects act on the length it returns.</summary>
        Path = 1
    }

    /// <summary>What a geometry-aware effect sees of Count positions (copies; device frame, mm;
    /// row-major: position i, cable c, coordinate k at [(4 * i + c) * 3 + k]).</summary>
    public sealed class EffectGeometry
    {
        /// <summary>What the values are: the cables' lengths (Path) or the readings (Reading).</summary>
        public EffectStage Stage { get; internal set; }
        public int Count { get; internal set; }
        /// <summary>Count x 3: the holder centre.</summary>
        public double[] Positions { get; internal set; }
        /// <summary>Count: acquisition time, s since the session's start (0 for live poses).</summary>
        public double[] TimeS { get; internal set; }
        /// <summary>Count x 4 x 3: each cable's anchor (exit point), after the model's geometry effects.</summary>
        public double[] Anchors { get; internal set; }
        /// <summary>Count x 4 x 3: each cable's attachment point on the holder.</summary>
        public double[] Holders { get; internal set; }
        /// <summary>Count x 4 x 3: unit vector from anchor to holder point.</summary>
        public double[] Unit { get; internal set; }
        /// <summary>Count x 4: straight distance from anchor to holder point.</summary>
        public double[] Chord { get; internal set; }
    }

    /// <summary>A geometry-aware user effect: changes values (Count x 4, the lengths or the
    /// readings) in place. Must be smooth in parameters and position (derivatives are central
    /// differences) and give row i the same whatever the other rows.</summary>
    public delegate void GeometryEffect(double[] parameters, EffectGeometry geometry, double[] values);

    /// <summary>User-defined effects (cdm_effect_register, CDM_EXPERIMENTAL): registered in the
    /// process for every later calibration load, fit and sim: master. A registration's
    /// callback is kept alive for the life of the process, even after Unregister: a calibration
    /// loaded while it was registered still calls it.</summary>
    public static class Effects
    {
        sealed class Registration
        {
            internal string Name;
            internal int NParams;
            internal GeometryEffect Apply;
            internal EffectGeomFn Trampoline;
            internal Exception LastError;
        }

        static readonly object Gate = new object();
        static readonly List<Registration> Kept = new List<Registration>();

        /// <summary>Registers apply as the effect `name` ([a-z0-9_]+). paramNames: identifiers, each
        /// once; paramScale: each parameter's typical magnitude (> 0); units, lower, upper, initial:
        /// one per parameter or null; origin: recorded in a calibration written with the effect
        /// (default "csharp:" and the delegate's declaring type).</summary>
        public static void Register(string name, string[] paramNames, double[] paramScale, GeometryEffect apply,
                                    EffectStage stage = EffectStage.Reading, string[] units = null,
                                    double[] lower = null, double[] upper = null, double[] initial = null,
                                    string doc = "", string origin = null)
        {
            if (name == null) throw new ArgumentNullException("name");
            if (apply == null) throw new ArgumentNullException("apply");
            NativeLoad.EnsureLoaded();
            if (paramNames == null) throw new ArgumentNullException("paramNames");
            int n = paramNames.Length;
            CheckNames(name, paramNames);
            CheckLength(name, "paramScale", paramScale, n, true);
            CheckLength(name, "lower", lower, n, false);
            CheckLength(name, "upper", upper, n, false);
            CheckLength(name, "initial", initial, n, false);
            if (units != null && units.Length != n)
                throw new ArgumentException("Effects.Register(" + name + "): units has " + units.Length + " values for " + n + " parameters", "units");
            var reg = new Registration { Name = name, NParams = n, Apply = apply };
            reg.Trampoline = (user, p, count, ctx, values) => Call(reg, p, count, ctx, values);
            if (origin == null && apply.Method.DeclaringType != null) origin = "csharp:" + apply.Method.DeclaringType.FullName;
            var mem = new List<IntPtr>();
            try
            {
                var d = new NativeEffectDef();
                d.struct_size = (uint)Marshal.SizeOf(typeof(NativeEffectDef));
                d.n_params = (uint)n;
                d.name = Utf8Z(name, mem);
                d.doc = Utf8Z(doc ?? "", mem);
                d.param_names = Strings(paramNames, mem);
                d.param_units = units == null ? IntPtr.Zero : Strings(units, mem);
                d.param_scale = Doubles(paramScale, mem);
                d.lower = Doubles(lower, mem);
                d.upper = Doubles(upper, mem);
                d.initial = Doubles(initial, mem);
                d.apply_geom = Marshal.GetFunctionPointerForDelegate(reg.Trampoline);
                d.origin = origin == null ? IntPtr.Zero : Utf8Z(origin, mem);
                d.stage = (uint)stage;
                lock (Gate)
                {
                    // Kept before the library can call it, and for good (see the class summary).
                    Kept.Add(reg);
                    Check.Ensure(NativeMethods.cdm_effect_register(ref d), "cdm_effect_register");
                }
            }
            finally
            {
                // The library copies names, units, scales, bounds and starts at registration.
                foreach (var p in mem) Marshal.FreeHGlobal(p);
            }
        }

        /// <summary>Removes a user effect (registered here, from Python or by a plugin).</summary>
        public static void Unregister(string name)
        {
            if (name == null) throw new ArgumentNullException("name");
            NativeLoad.EnsureLoaded();
            Check.Ensure(NativeMethods.cdm_effect_unregister(Z(name)), "cdm_effect_unregister");
        }

        /// <summary>Loads a plugin (a path to a shared object exporting cdm_plugin_init).</summary>
        public static void LoadPlugin(string path)
        {
            if (path == null) throw new ArgumentNullException("path");
            NativeLoad.EnsureLoaded();
            Check.Ensure(NativeMethods.cdm_effect_load_plugin(Z(path)), "cdm_effect_load_plugin");
        }

        /// <summary>Every effect the library knows: built-in first, then user ones.</summary>
        public static string[] Names
        {
            get
            {
                NativeLoad.EnsureLoaded();
                int n = (int)NativeMethods.cdm_effect_count().ToUInt64();
                var r = new string[n];
                for (int i = 0; i < n; i++) r[i] = NativeMethods.Utf8(NativeMethods.cdm_effect_name(new UIntPtr((uint)i)));
                return r;
            }
        }

        /// <summary>The fingerprint (16 hex digits) of effect `name`'s stage, parameter names and units.</summary>
        public static string Fingerprint(string name)
        {
            var names = Names;
            for (int i = 0; i < names.Length; i++)
            {
                if (names[i] != name) continue;
                var buf = new byte[17];
                IntPtr origin;
                Check.Ensure(NativeMethods.cdm_effect_fingerprint(new UIntPtr((uint)i), buf, new UIntPtr(17), out origin),
                             "cdm_effect_fingerprint");
                return Encoding.ASCII.GetString(buf, 0, 16);
            }
            throw new ArgumentException("no effect named \"" + name + "\"", "name");
        }

        /// <summary>The exception the effect's last failing call threw (the fit or load that called
        /// it failed with a code), or null.</summary>
        public static Exception LastError(string name)
        {
            lock (Gate)
                for (int i = Kept.Count - 1; i >= 0; i--)
                    if (Kept[i].Name == name) return Kept[i].LastError;
            return null;
        }

        // Runs on whatever thread the library evaluates the model on (a fit's, the device's
        // reader thread): no exception may unwind into native code.
        static int Call(Registration reg, IntPtr p, UIntPtr count, IntPtr ctxPtr, IntPtr valuesPtr)
        {
            try
            {
                int n = checked((int)count.ToUInt64());
                if (n == 0) return 0;
                var c = (NativeEffectContext)Marshal.PtrToStructure(ctxPtr, typeof(NativeEffectContext));
                var prm = new double[reg.NParams];
                if (reg.NParams > 0) Marshal.Copy(p, prm, 0, reg.NParams);
                var g = new EffectGeometry
                {
                    Stage = (EffectStage)c.stage, Count = n,
                    Positions = Copy(c.positions_mm, 3 * n), TimeS = Copy(c.t_s, n),
                    Anchors = Copy(c.anchors_mm, 12 * n), Holders = Copy(c.holders_mm, 12 * n),
                    Unit = Copy(c.unit, 12 * n), Chord = Copy(c.chord_mm, 4 * n)
                };
                var values = Copy(valuesPtr, 4 * n);
                reg.Apply(prm, g, values);
                if (values.Length != 4 * n) throw new InvalidOperationException("values resized");
                Marshal.Copy(values, 0, valuesPtr, 4 * n);
                return 0;
            }
            catch (Exception e)
            {
                reg.LastError = e;
                return (int)ErrorCode.Internal;
            }
        }

        static double[] Copy(IntPtr p, int count)
        {
            var a = new double[count];
            Marshal.Copy(p, a, 0, count);
            return a;
        }

        static void CheckNames(string name, string[] paramNames)
        {
            var seen = new HashSet<string>();
            for (int k = 0; k < paramNames.Length; k++)
            {
                var p = paramNames[k];
                if (p == null || !Regex.IsMatch(p, "^[A-Za-z_][A-Za-z0-9_]*$"))
                    throw new ArgumentException("Effects.Register(" + name + "): parameter " + k + "'s name \"" + p +
                                                "\" is not an identifier ([A-Za-z_][A-Za-z0-9_]*)", "paramNames");
                if (!seen.Add(p))
                    throw new ArgumentException("Effects.Register(" + name + "): parameter name \"" + p + "\" is given twice", "paramNames");
            }
        }

        static void CheckLength(string name, string what, double[] v, int n, bool required)
        {
            if (v == null && !required) return;
            if (v == null || v.Length != n)
                throw new ArgumentException("Effects.Register(" + name + "): " + what + " needs " + n + " values, got " +
                                            (v == null ? "null" : v.Length.ToString()), what);
        }

        static byte[] Z(string s)
        {
            var b = Encoding.UTF8.GetBytes(s);
            var z = new byte[b.Length + 1];
            Array.Copy(b, z, b.Length);
            return z;
        }

        static IntPtr Utf8Z(string s, List<IntPtr> mem)
        {
            var z = Z(s);
            var p = Marshal.AllocHGlobal(z.Length);
            mem.Add(p);
            Marshal.Copy(z, 0, p, z.Length);
            return p;
        }

        static IntPtr Strings(string[] items, List<IntPtr> mem)
        {
            var p = Marshal.AllocHGlobal(IntPtr.Size * Math.Max(items.Length, 1));
            mem.Add(p);
            for (int i = 0; i < items.Length; i++) Marshal.WriteIntPtr(p, i * IntPtr.Size, Utf8Z(items[i], mem));
            return p;
        }

        static IntPtr Doubles(double[] v, List<IntPtr> mem)
        {
            if (v == null) return IntPtr.Zero;
            var p = Marshal.AllocHGlobal(sizeof(double) * Math.Max(v.Length, 1));
            mem.Add(p);
            if (v.Length > 0) Marshal.Copy(v, 0, p, v.Length);
            return p;
        }
    }
}
