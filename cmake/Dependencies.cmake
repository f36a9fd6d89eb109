# Every dependency comes from Debian 12 packages (see scripts/install-deps.sh).
# With DN_WITH_OIIO=OFF only Threads, LibTorch and (for the tests) doctest.
find_package(Threads REQUIRED)
if(DN_WITH_OIIO)
  find_package(PkgConfig REQUIRED)
  find_package(fmt REQUIRED)
  find_package(nlohmann_json 3 REQUIRED)  # Debian: nlohmann-json3-dev

  # Debian's OpenImageIO and OpenColorIO CMake configs carry broken include
  # paths; their pkg-config files give clean imported targets.
  pkg_check_modules(OIIO REQUIRED IMPORTED_TARGET OpenImageIO)
  pkg_check_modules(OCIO REQUIRED IMPORTED_TARGET OpenColorIO)
  pkg_check_modules(IMATH REQUIRED IMPORTED_TARGET Imath)  # half floats (OpenEXR's own)
  pkg_check_modules(OPENEXR REQUIRED IMPORTED_TARGET OpenEXR)  # channels read by name
endif()

if(DN_BUILD_TESTS)
  find_package(doctest REQUIRED)
endif()

if(DN_WITH_TORCH)
  find_package(Torch REQUIRED)
endif()
