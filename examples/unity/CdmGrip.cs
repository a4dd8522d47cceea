// CdmGrip: drives a GameObject from the cable-driven master.
//
// Drop Cdm.dll and Cdm.dll.config into Assets/Plugins (and libcdm.so.1 where
// the player can load it: Assets/Plugins/x86_64, or the system), add this
// component to the object the grip should move, press Play.
//
// Frames. The device reports mm in a right-handed frame whose y-z plane is the
// cable plane and whose x axis leaves that plane (docs/protocol.md). Unity is
// left-handed, metres, y up. With the master standing upright in front of the
// user (cable plane vertical, facing them: device z up, device y to the user's
// right, device x toward the user):
//     unity.x =  device.y      (right)
//     unity.y =  device.z      (up)
//     unity.z = -device.x      (forward, away from the user)
// This map has determinant -1 (it is what turns right- into left-handed), so a
// rotation's axis maps like a vector and its sense flips: the device's
// quaternion (w, x, y, z) becomes Unity's (x, y, z, w) = (-y, -z, x, w)
// (DeviceToUnity below). A master mounted differently changes only these two
// functions.
using System;
using UnityEngine;

public class CdmGrip : MonoBehaviour
{
    [SerializeField] string uri = "";              // "" : $CDM_DEVICE or the first master; "sim:" to try without one
    [SerializeField] float metresPerMm = 0.001f;   // 1:1 by default; motion scaling goes here
    [SerializeField] Vector3 deviceOriginInUnity = Vector3.zero; // where the device's (0,0,0) sits, local space
    [SerializeField] string calibrationPath = "";  // optional calibration JSON (`cdm calib fit`)

    Cdm.Device device;
    /// <summary>The last pose read (Status, Flags, buttons...), for other scripts.</summary>
    public Cdm.Pose LastPose { get; private set; }
    public bool HasPose { get; private set; }

    void OnEnable()
    {
        try
        {
            device = Cdm.Device.Open(string.IsNullOrEmpty(uri) ? null : uri);
            if (!string.IsNullOrEmpty(calibrationPath))
                using (var cal = Cdm.Calibration.Load(calibrationPath)) device.SetCalibration(cal); // the library copies it
        }
        catch (Cdm.CdmException e)
        {
            Debug.LogError("CdmGrip: " + e.Message);
            if (device != null) { device.Dispose(); device = null; }
            enabled = false;
        }
    }

    void Update()
    {
        if (device == null) return;
        Cdm.Pose pose;
        // No exception, no allocation: fine every frame. True for a pose to use
        // (current, or the last good one when stale, disconnected or ended).
        if (!device.TryGetPose(out pose))
        {
            if (pose.Status != Cdm.ErrorCode.NoData) // NoData: nothing yet
                Debug.LogWarning("CdmGrip: cdm_get_pose returned " + pose.Status);
            return;
        }
        LastPose = pose;
        HasPose = true;
        // A stale or disconnected pose is the last good one: holding it still is right.
        transform.localPosition = deviceOriginInUnity + DeviceToUnity(pose.Position, metresPerMm);
        transform.localRotation = DeviceToUnity(pose.Orientation);
    }

    void OnDisable()
    {
        if (device != null) device.Dispose(); // stops the reader thread
        device = null;
        HasPose = false;
    }

    /// <summary>Device position (mm) to Unity local position (m): see the frame note above.</summary>
    public static Vector3 DeviceToUnity(Cdm.Vector3d p, float metresPerMm)
    {
        return new Vector3((float)p.Y * metresPerMm, (float)p.Z * metresPerMm, -(float)p.X * metresPerMm);
    }

    /// <summary>Device orientation to Unity rotation: axis mapped like a position, sense flipped.</summary>
    public static Quaternion DeviceToUnity(Cdm.Quaterniond q)
    {
        return new Quaternion(-(float)q.Y, -(float)q.Z, (float)q.X, (float)q.W);
    }
}
