# Packaging: the Python wheel's copy of libcdm, the .deb (CPack) and the
# NuGet package. Included at the end of the top-level CMakeLists.txt, after
# every install() rule of the ordinary `cmake --install`.

# --- Python wheel (scikit-build-core sets SKBUILD; pyproject asks for the
# "python" component only). One real file named by the SONAME, beside the
# package, where cdm/_native.py looks second: a wheel cannot hold symlinks.
if(SKBUILD)
  install(FILES $<TARGET_FILE:cdm> DESTINATION cdm RENAME libcdm.so.${CDM_SOVERSION}
          COMPONENT python)
  # The `cdm` command as cdm/bin/cdm, run by the wheel's `cdm` entry point
  # (bindings/python/cdm/_cli.py); it finds the library one level up.
  set_target_properties(cdm-cli PROPERTIES INSTALL_RPATH "$ORIGIN/..")
  install(TARGETS cdm-cli RUNTIME DESTINATION cdm/bin COMPONENT python)
  # install(FILES) does not strip: without this the wheel carries ~70 MB of DWARF.
  install(CODE "execute_process(COMMAND \"${CMAKE_STRIP}\" --strip-debug
                \"\${CMAKE_INSTALL_PREFIX}/cdm/libcdm.so.${CDM_SOVERSION}\"
                \"\${CMAKE_INSTALL_PREFIX}/cdm/bin/cdm\")" COMPONENT python)
endif()

# --- The Python package (binding and report tool) where Debian's python3
# imports it, so `cdm calib diagnose --report` works from the .deb alone
# (cdm finds it there too under another prefix: src/cli/report_spawn.cpp).
# The wheel carries it itself.
if(NOT SKBUILD)
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/bindings/python/cdm DESTINATION lib/python3/dist-packages
          PATTERN "__pycache__" EXCLUDE PATTERN "*.pyc" EXCLUDE PATTERN "report.py" EXCLUDE)
endif()

# --- Mono: the installed Cdm.dll.config maps "cdm" to the installed library
# by absolute path, so an installed program needs no LD_LIBRARY_PATH even
# under a prefix the dynamic linker does not search. Written at install time
# because `cmake --install --prefix` may differ from CMAKE_INSTALL_PREFIX.
if(CDM_BUILD_CSHARP AND TARGET cdm_csharp)
  install(CODE "
    set(_lib \"\${CMAKE_INSTALL_PREFIX}/${CMAKE_INSTALL_LIBDIR}/libcdm.so.${CDM_SOVERSION}\")
    file(WRITE \"\$ENV{DESTDIR}\${CMAKE_INSTALL_PREFIX}/${CMAKE_INSTALL_LIBDIR}/cdm/csharp/Cdm.dll.config\"
\"<!-- Written by cmake --install: the library installed with this Cdm.dll. -->
<configuration>
  <dllmap dll=\\\"cdm\\\" os=\\\"linux\\\" target=\\\"\${_lib}\\\"/>
</configuration>
\")")
endif()

# --- Debian package (cpack -G DEB in the build directory).
# Licence text: the copyright file Debian policy wants in /usr/share/doc.
configure_file(${CMAKE_CURRENT_LIST_DIR}/copyright.in ${CMAKE_CURRENT_BINARY_DIR}/copyright @ONLY)
install(FILES ${CMAKE_CURRENT_BINARY_DIR}/copyright DESTINATION ${CMAKE_INSTALL_DOCDIR})
# The README and the documentation beside it, for a machine without the clone.
install(FILES ${PROJECT_SOURCE_DIR}/README.md DESTINATION ${CMAKE_INSTALL_DOCDIR})
install(DIRECTORY ${PROJECT_SOURCE_DIR}/docs/ DESTINATION ${CMAKE_INSTALL_DOCDIR}/docs)

set(CPACK_PACKAGE_NAME "cdm")
set(CPACK_PACKAGE_VENDOR "cdm project")
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "${PROJECT_DESCRIPTION}")
set(CPACK_PACKAGE_CONTACT "cdm maintainers <cdm@localhost>")
set(CPACK_RESOURCE_FILE_LICENSE ${CMAKE_CURRENT_BINARY_DIR}/copyright)
set(CPACK_GENERATOR "DEB")
set(CPACK_PACKAGING_INSTALL_PREFIX "/usr")
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_SECTION "libs")
# No Homepage field: the project has no public home page to name.
# The Depends line (libhidapi-hidraw0, libnlopt0, libstdc++6, libc6, ...)
# comes from dpkg-shlibdeps on the packaged binaries, not from a list here.
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
# RelWithDebInfo carries ~300 MB of DWARF; a package ships stripped binaries.
set(CPACK_STRIP_FILES ON)
set(CPACK_DEBIAN_PACKAGE_GENERATE_SHLIBS ON)
# pkg-config is what cdm.pc is for; udev reads the rule.
set(CPACK_DEBIAN_PACKAGE_RECOMMENDS "pkg-config, udev")
# One package with everything `cmake --install` installs (the wheel's
# "python" component exists only under scikit-build-core).
include(CPack)

# --- NuGet package: `ninja cdm_nupkg` writes build/nuget/Cdm.<version>.nupkg.
# Debian's nuget (Mono) packs it. Cdm.dll.config there maps "cdm" to the
# SONAME, which Mono finds beside the assembly: the layout a consumer gets
# when NuGet copies lib/ and runtimes/linux-x64/native/ to its output.
find_program(CDM_NUGET nuget)
find_package(Python3 COMPONENTS Interpreter QUIET)
if(CDM_NUGET AND TARGET cdm_csharp AND Python3_Interpreter_FOUND)
  set(_nu ${PROJECT_BINARY_DIR}/nuget)
  configure_file(${PROJECT_SOURCE_DIR}/bindings/csharp/Cdm.nuspec.in ${_nu}/stage/Cdm.nuspec @ONLY)
  add_custom_command(
    OUTPUT ${_nu}/Cdm.${PROJECT_VERSION}.nupkg
    COMMAND ${CMAKE_COMMAND} -E copy ${PROJECT_BINARY_DIR}/bindings/csharp/Cdm.dll
            ${PROJECT_BINARY_DIR}/bindings/csharp/Cdm.dll.config ${_nu}/stage/
    COMMAND ${CMAKE_STRIP} --strip-debug -o ${_nu}/stage/libcdm.so.${CDM_SOVERSION} $<TARGET_FILE:cdm>
    COMMAND ${CDM_NUGET} pack ${_nu}/stage/Cdm.nuspec -BasePath ${_nu}/stage -OutputDirectory ${_nu}
            -NonInteractive -Verbosity quiet
    # Debian's nuget packs licenseUrl only: the licence expression goes in after.
    COMMAND ${Python3_EXECUTABLE} ${CMAKE_CURRENT_LIST_DIR}/nupkg_license.py
            ${_nu}/Cdm.${PROJECT_VERSION}.nupkg Apache-2.0
    DEPENDS cdm cdm_csharp ${_nu}/stage/Cdm.nuspec ${CMAKE_CURRENT_LIST_DIR}/nupkg_license.py
    COMMENT "nuget: Cdm.${PROJECT_VERSION}.nupkg"
    VERBATIM)
  add_custom_target(cdm_nupkg DEPENDS ${_nu}/Cdm.${PROJECT_VERSION}.nupkg)
endif()
