using System;

namespace Cdm
{
    /// <summary>
    /// The pose in other conventions: metres and quaternions x, y, z, w, in
    /// ROS's REP 103 frame or in Unity's (docs/bindings.md, "Frames").
    /// Device frame: right-handed, mm, the y-z plane is the cable plane. The
    /// master upright in front of the user: device x toward the user, y to
    /// their right, z up. ROS (x forward, away from the user; y left; z up):
    /// (-x, -y, z), a half turn about z. Unity (left-handed; x right, y up,
    /// z forward): (y, z, -x), determinant -1. A rotation follows the same
    /// change of frame (its axis maps like a pseudovector, det(C) C axis),
    /// so q' keeps the component formula v' = q' v q'^-1 both engines use.
    /// A master mounted another way changes only the matrix (ToFrame).
    /// </summary>
    public static class Frames
    {
        public static readonly double[,] RosFromDevice = { { -1, 0, 0 }, { 0, -1, 0 }, { 0, 0, 1 } };
        public static readonly double[,] UnityFromDevice = { { 0, 1, 0 }, { 0, 0, 1 }, { -1, 0, 0 } };

        /// <summary>Position in metres and quaternion (x, y, z, w) in the frame
        /// whose axes are the rows of <paramref name="frame"/> (orthonormal, device to target).</summary>
        public static void ToFrame(Pose pose, double[,] frame, out Vector3d positionM, out double[] quaternionXyzw)
        {
            if (frame == null || frame.GetLength(0) != 3 || frame.GetLength(1) != 3)
                throw new ArgumentException("Frames.ToFrame: frame must be a 3x3 matrix");
            double det = frame[0, 0] * (frame[1, 1] * frame[2, 2] - frame[1, 2] * frame[2, 1])
                       - frame[0, 1] * (frame[1, 0] * frame[2, 2] - frame[1, 2] * frame[2, 0])
                       + frame[0, 2] * (frame[1, 0] * frame[2, 1] - frame[1, 1] * frame[2, 0]);
            if (!(Math.Abs(Math.Abs(det) - 1) < 1e-9))
                throw new ArgumentException("Frames.ToFrame: frame must be orthonormal (determinant +-1), got " + det);
            var q = pose.Orientation;
            double n = q.Norm;
            if (!(n > 0) || double.IsInfinity(n))
                throw new ArgumentException("Frames.ToFrame: the orientation is not a non-zero finite quaternion");
            Vector3d axis = Apply(frame, new Vector3d(q.X / n, q.Y / n, q.Z / n));
            quaternionXyzw = new[] { det * axis.X, det * axis.Y, det * axis.Z, q.W / n };
            Vector3d p = Apply(frame, pose.Position);
            positionM = new Vector3d(p.X / 1000.0, p.Y / 1000.0, p.Z / 1000.0);
        }

        /// <summary>The pose in ROS's REP 103 frame, metres, quaternion x, y, z, w.</summary>
        public static void ToRos(Pose pose, out Vector3d positionM, out double[] quaternionXyzw)
        {
            ToFrame(pose, RosFromDevice, out positionM, out quaternionXyzw);
        }

        /// <summary>The pose in Unity's frame (left-handed, y up), metres, quaternion x, y, z, w.</summary>
        public static void ToUnity(Pose pose, out Vector3d positionM, out double[] quaternionXyzw)
        {
            ToFrame(pose, UnityFromDevice, out positionM, out quaternionXyzw);
        }

        static Vector3d Apply(double[,] c, Vector3d v)
        {
            return new Vector3d(c[0, 0] * v.X + c[0, 1] * v.Y + c[0, 2] * v.Z,
                                c[1, 0] * v.X + c[1, 1] * v.Y + c[1, 2] * v.Z,
                                c[2, 0] * v.X + c[2, 1] * v.Y + c[2, 2] * v.Z);
        }
    }
}
