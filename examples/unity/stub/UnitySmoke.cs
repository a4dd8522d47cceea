// Runs CdmGrip's life cycle against the stand-in UnityEngine and the simulated
// master, and checks the frame mapping. Exit code = failed checks.
using System;
using System.Reflection;
using UnityEngine;

static class UnitySmoke
{
    static int failures;

    static void Expect(bool ok, string what)
    {
        if (!ok) { failures++; Console.WriteLine("FAIL: " + what); }
    }

    static void Call(object o, string method)
    {
        o.GetType().GetMethod(method, BindingFlags.Instance | BindingFlags.NonPublic | BindingFlags.Public).Invoke(o, null);
    }

    // Hamilton rotation of v by unit quaternion (w, x, y, z), in doubles, in the device frame.
    static double[] Rotate(Cdm.Quaterniond q, double[] v)
    {
        double tx = 2 * (q.Y * v[2] - q.Z * v[1]), ty = 2 * (q.Z * v[0] - q.X * v[2]), tz = 2 * (q.X * v[1] - q.Y * v[0]);
        return new[] { v[0] + q.W * tx + (q.Y * tz - q.Z * ty), v[1] + q.W * ty + (q.Z * tx - q.X * tz),
                       v[2] + q.W * tz + (q.X * ty - q.Y * tx) };
    }

    static int Main()
    {
        // Life cycle on a still master: (50, 0, 0) mm is 5 cm toward the user, -z in Unity.
        var grip = new CdmGrip();
        typeof(CdmGrip).GetField("uri", BindingFlags.Instance | BindingFlags.NonPublic)
            .SetValue(grip, "sim:?motion=still&noise=0&imu_noise=0");
        Call(grip, "OnEnable");
        Expect(grip.enabled, "OnEnable failed to open sim:");
        for (int i = 0; i < 200 && !grip.HasPose; i++) { System.Threading.Thread.Sleep(5); Call(grip, "Update"); }
        Expect(grip.HasPose, "no pose after 1 s of Update");
        var p = grip.transform.localPosition;
        // Quantisation of the still pose is well below 0.1 mm = 1e-4 m.
        Expect(Math.Abs(p.x) < 1e-4 && Math.Abs(p.y) < 1e-4 && Math.Abs(p.z + 0.050) < 1e-4, "still pose in Unity " + p);
        var r = grip.transform.localRotation;
        Expect(Math.Abs(r.w - 1) < 1e-4, "still rotation in Unity " + r);
        Call(grip, "OnDisable");
        Call(grip, "OnDisable"); // twice: Unity calls it once, but the component must not care

        // A bad URI disables the component with an error instead of throwing.
        var bad = new CdmGrip();
        typeof(CdmGrip).GetField("uri", BindingFlags.Instance | BindingFlags.NonPublic).SetValue(bad, "nosuchscheme:");
        Call(bad, "OnEnable");
        Expect(!bad.enabled, "a bad URI left the component enabled");

        // The mapping: the device axes go to Unity right / up / forward...
        var ux = CdmGrip.DeviceToUnity(new Cdm.Vector3d(1, 0, 0), 1);
        var uy = CdmGrip.DeviceToUnity(new Cdm.Vector3d(0, 1, 0), 1);
        var uz = CdmGrip.DeviceToUnity(new Cdm.Vector3d(0, 0, 1), 1);
        Expect(ux.z == -1 && uy.x == 1 && uz.y == 1, "axes map to " + ux + uy + uz);
        // ...and rotations commute with it: map(R v) == R' map(v), for the random
        // motion's orientations and three test vectors.
        using (var dev = Cdm.Device.Open("sim:?motion=random&seed=7"))
        {
            double worst = 0;
            for (int i = 0; i < 50; i++)
            {
                var q = dev.WaitPose(1000).Orientation;
                foreach (var v in new[] { new[] { 1.0, 0, 0 }, new[] { 0, 1.0, 0 }, new[] { 0.3, -0.5, 0.8 } })
                {
                    var rv = Rotate(q, v);
                    var lhs = CdmGrip.DeviceToUnity(new Cdm.Vector3d(rv[0], rv[1], rv[2]), 1);
                    var rhs = CdmGrip.DeviceToUnity(q) * CdmGrip.DeviceToUnity(new Cdm.Vector3d(v[0], v[1], v[2]), 1);
                    worst = Math.Max(worst, (lhs - rhs).magnitude);
                }
            }
            // float arithmetic on unit vectors: a few 1e-7.
            Expect(worst < 1e-5, "rotation mapping off by " + worst);
        }
        Console.WriteLine(failures == 0 ? "CdmGrip OK" : failures + " failures");
        return failures;
    }
}
