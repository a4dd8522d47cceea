using System.Reflection;

[assembly: AssemblyTitle("Cdm")]
[assembly: AssemblyDescription("P/Invoke binding of libcdm, the cable-driven haptic master driver")]
[assembly: AssemblyVersion("1.2.0.0")] // = CMakeLists.txt project(VERSION); tests/cli/test_abi_version.py checks it
[assembly: AssemblyInformationalVersion("1.2.0")]
