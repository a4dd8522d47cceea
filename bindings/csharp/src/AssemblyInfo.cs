using System.Reflection;

[assembly: AssemblyTitle("Cdm")]
[assembly: AssemblyDescription("P/Invoke binding of libcdm, the cable-driven haptic master driver")]
[assembly: AssemblyVersion("1.0.0.0")]
