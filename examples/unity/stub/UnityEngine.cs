// A minimal stand-in for the UnityEngine types CdmGrip uses, so that the
// example compiles (and its frame mapping can be exercised) without Unity.
// Not Unity: only what CdmGrip touches, with Unity's semantics where it matters
// (Quaternion(x, y, z, w) order, Quaternion * Vector3 rotation).
using System;

namespace UnityEngine
{
    [AttributeUsage(AttributeTargets.Field)]
    public sealed class SerializeField : Attribute { }

    public struct Vector3
    {
        public float x, y, z;
        public Vector3(float x, float y, float z) { this.x = x; this.y = y; this.z = z; }
        public static readonly Vector3 zero = new Vector3(0, 0, 0);
        public static Vector3 operator +(Vector3 a, Vector3 b) { return new Vector3(a.x + b.x, a.y + b.y, a.z + b.z); }
        public static Vector3 operator -(Vector3 a, Vector3 b) { return new Vector3(a.x - b.x, a.y - b.y, a.z - b.z); }
        public float magnitude { get { return (float)Math.Sqrt(x * x + y * y + z * z); } }
        public override string ToString() { return string.Format("({0:F4}, {1:F4}, {2:F4})", x, y, z); }
    }

    public struct Quaternion
    {
        public float x, y, z, w;
        public Quaternion(float x, float y, float z, float w) { this.x = x; this.y = y; this.z = z; this.w = w; }
        public static readonly Quaternion identity = new Quaternion(0, 0, 0, 1);

        // Unity's formula: v' = v + 2 w (u x v) + 2 u x (u x v), u = (x, y, z).
        public static Vector3 operator *(Quaternion q, Vector3 v)
        {
            float tx = 2 * (q.y * v.z - q.z * v.y), ty = 2 * (q.z * v.x - q.x * v.z), tz = 2 * (q.x * v.y - q.y * v.x);
            return new Vector3(v.x + q.w * tx + (q.y * tz - q.z * ty),
                               v.y + q.w * ty + (q.z * tx - q.x * tz),
                               v.z + q.w * tz + (q.x * ty - q.y * tx));
        }
        public override string ToString() { return string.Format("({0:F4}, {1:F4}, {2:F4}, {3:F4})", x, y, z, w); }
    }

    public class Transform
    {
        public Vector3 localPosition;
        public Quaternion localRotation = Quaternion.identity;
    }

    public class Object { }

    public class Component : Object
    {
        readonly Transform t = new Transform();
        public Transform transform { get { return t; } }
    }

    public class Behaviour : Component
    {
        public bool enabled = true;
    }

    public class MonoBehaviour : Behaviour { }

    public static class Debug
    {
        public static void Log(object message) { Console.WriteLine(message); }
        public static void LogWarning(object message) { Console.WriteLine("warning: " + message); }
        public static void LogError(object message) { Console.Error.WriteLine("error: " + message); }
    }
}
