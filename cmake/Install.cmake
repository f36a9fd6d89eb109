# Install rules: `cmake --install build --prefix /opt/dn` gives the tools, their
# docs, the shipped models, the libraries with their headers, a CMake package
# (find_package(DiffusionDenoise) -> dn::tonemap, dn::ocio, dn::metrics,
# dn::buffers, dn::reproject, dn::io, dn::data, dn::motion, dn::infer,
# dn::temporal_device, dn::denoise, dn::temporal) and pkg-config files (dn-tonemap, dn-metrics, dn-io,
# dn-denoise, dn-temporal). Everything is relocatable: the
# package files find the prefix from their own place. Built with
# DN_WITH_OIIO=OFF: the libraries that build (dn::tonemap, dn::metrics,
# dn::buffers, dn::reproject, dn::infer, dn::temporal_device), the CMake package and the models, no tools and no
# pkg-config files (theirs require OpenColorIO and OpenImageIO).
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(DN_INSTALL_DATADIR ${CMAKE_INSTALL_DATADIR}/${PROJECT_NAME})
set(DN_INSTALL_CMAKEDIR ${CMAKE_INSTALL_LIBDIR}/cmake/DiffusionDenoise)

# Library target -> name after the dn:: namespace.
set(dn_exports dn_tonemap tonemap dn_metrics metrics dn_buffers buffers dn_reproject reproject)
if(DN_WITH_OIIO)
  list(APPEND dn_exports dn_tonemap_ocio ocio dn_io io dn_data data dn_motion motion)
endif()
if(DN_WITH_TORCH)
  list(APPEND dn_exports dn_infer infer dn_temporal_device temporal_device)
endif()
if(TARGET dn_core)
  list(APPEND dn_exports dn_core denoise)
endif()
if(TARGET dn_temporal)
  list(APPEND dn_exports dn_temporal temporal)
endif()
set(dn_libraries)
while(dn_exports)
  list(POP_FRONT dn_exports target name)
  set_target_properties(${target} PROPERTIES EXPORT_NAME ${name})
  target_include_directories(${target} INTERFACE $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
  target_compile_features(${target} INTERFACE cxx_std_17)
  list(APPEND dn_libraries ${target})
endwhile()

install(TARGETS ${dn_libraries} EXPORT DiffusionDenoiseTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
        LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
        RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
install(DIRECTORY libtonemap/include/ libmetrics/include/ libdenoise/include/
        DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
install(EXPORT DiffusionDenoiseTargets NAMESPACE dn:: DESTINATION ${DN_INSTALL_CMAKEDIR})
configure_package_config_file(cmake/DiffusionDenoiseConfig.cmake.in
                              ${CMAKE_CURRENT_BINARY_DIR}/DiffusionDenoiseConfig.cmake
                              INSTALL_DESTINATION ${DN_INSTALL_CMAKEDIR}
                              PATH_VARS DN_INSTALL_DATADIR)
write_basic_package_version_file(${CMAKE_CURRENT_BINARY_DIR}/DiffusionDenoiseConfigVersion.cmake
                                 COMPATIBILITY SameMinorVersion)
install(FILES ${CMAKE_CURRENT_BINARY_DIR}/DiffusionDenoiseConfig.cmake
              ${CMAKE_CURRENT_BINARY_DIR}/DiffusionDenoiseConfigVersion.cmake
        DESTINATION ${DN_INSTALL_CMAKEDIR})

# pkg-config: static libraries, so each file lists what linking needs. The
# prefix is found from the .pc file's own folder.
file(RELATIVE_PATH DN_PC_PREFIX "/${CMAKE_INSTALL_LIBDIR}/pkgconfig" "/")
set(dn_pkgconfig)
if(DN_WITH_OIIO)
  list(APPEND dn_pkgconfig dn-tonemap dn-metrics dn-io)
endif()
if(TARGET dn_core)
  # LibTorch has no .pc file: its include folders and libraries, from its CMake package.
  # (/usr/include stays out: -isystem on it breaks the C++ headers' #include_next;
  # libtorch itself is linked as needed or not, as its own torch_library target does.)
  set(DN_TORCH_CFLAGS "${TORCH_CXX_FLAGS}")
  foreach(dir ${TORCH_INCLUDE_DIRS})
    if(NOT dir STREQUAL "/usr/include")
      string(APPEND DN_TORCH_CFLAGS " -isystem ${dir}")
    endif()
  endforeach()
  get_filename_component(DN_TORCH_LIBDIR "${TORCH_LIBRARY}" DIRECTORY)
  set(DN_TORCH_LINK "-Wl,--no-as-needed -ltorch -Wl,--as-needed -ltorch_cpu -lc10")
  set(DN_GLOO_LIBRARY "${GLOO_LIBRARY}")
  list(APPEND dn_pkgconfig dn-denoise dn-temporal)
endif()
foreach(pc ${dn_pkgconfig})
  configure_file(cmake/pkgconfig/${pc}.pc.in ${CMAKE_CURRENT_BINARY_DIR}/pkgconfig/${pc}.pc @ONLY)
  install(FILES ${CMAKE_CURRENT_BINARY_DIR}/pkgconfig/${pc}.pc
          DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig)
endforeach()

# The tools, their docs, the shipped models and the built-in OCIO config.
set(dn_tools)
if(DN_WITH_OIIO)
  list(APPEND dn_tools dnmetrics)
endif()
if(TARGET dn_core)
  list(APPEND dn_tools dndenoise dntrain dncleanse)
endif()
install(TARGETS ${dn_tools} RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
install(FILES README.md DESTINATION ${CMAKE_INSTALL_DOCDIR})
install(DIRECTORY docs/ DESTINATION ${CMAKE_INSTALL_DOCDIR}/docs)
install(DIRECTORY models/ DESTINATION ${DN_INSTALL_DATADIR}/models)
if(DN_WITH_OIIO)
  install(FILES libtonemap/ocio/srgb.ocio DESTINATION ${DN_INSTALL_DATADIR}/ocio)
endif()
