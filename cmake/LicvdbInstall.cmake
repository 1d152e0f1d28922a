# Install rules and packaging: `cmake --install build --prefix P` and `cpack -G DEB` (in build/).
#
#   P/bin/licvdb                              the command-line tool
#   P/libexec/licvdb/licvdb-readcheck         the child of every .vdb read (found relative to licvdb)
#   P/libexec/licvdb/licvdb-image.so          the image module: OIIO, OCIO (loaded on first use)
#   P/libexec/licvdb/licvdb-mesh.so           the mesh module: VTK (loaded on first use; with VTK)
#   P/share/licvdb/ocio/                      the raycaster's OCIO config (found relative to the binary)
#   P/share/licvdb/blender/*.zip              the Blender add-on (scripts/package-addon)
#   P/include/lic, P/include/vdbexport        public headers
#   P/lib/liblic.a, P/lib/libvdbexport.a      the libraries (static)
#   P/lib/cmake/licvdb/                       find_package(licvdb): lic::lic, lic::vdbexport
#
# Components: `runtime` (tool, config, add-on) and `development` (headers, libraries, CMake
# package), packaged as licvdb and licvdb-dev. tests/install and scripts/test-install check both.
include(CMakePackageConfigHelpers)

set(LICVDB_CMAKE_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/licvdb)

# --- runtime --------------------------------------------------------------------------------
install(TARGETS licvdb RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR} COMPONENT runtime)
# The child of every .vdb read, found by licvdb in its ../libexec/licvdb/ (VdbCheck.h).
install(TARGETS licvdb-readcheck RUNTIME DESTINATION ${CMAKE_INSTALL_LIBEXECDIR}/licvdb COMPONENT runtime)
# The image module (OpenImageIO, OpenColorIO), loaded by licvdb from its ../libexec/licvdb/ (ImageIO.h).
install(TARGETS licvdb-image LIBRARY DESTINATION ${CMAKE_INSTALL_LIBEXECDIR}/licvdb COMPONENT runtime)
# The mesh module (VTK's readers), loaded by licvdb from its ../libexec/licvdb/ (MeshInput.h).
if(LICVDB_VTK)
  install(TARGETS licvdb-mesh LIBRARY DESTINATION ${CMAKE_INSTALL_LIBEXECDIR}/licvdb COMPONENT runtime)
endif()
install(DIRECTORY ${PROJECT_SOURCE_DIR}/share/ocio/ DESTINATION ${CMAKE_INSTALL_DATADIR}/licvdb/ocio
        COMPONENT runtime)
# The add-on zips, made at build time (scripts/package-addon) so that install only copies.
file(GLOB_RECURSE _licvdb_addon_files CONFIGURE_DEPENDS ${PROJECT_SOURCE_DIR}/blender_addon/licvdb/*.py
     ${PROJECT_SOURCE_DIR}/blender_addon/licvdb/*.toml)
set(_licvdb_addon_dir ${PROJECT_BINARY_DIR}/blender)
set(_licvdb_addon_zips ${_licvdb_addon_dir}/licvdb-blender-addon.zip ${_licvdb_addon_dir}/licvdb-blender-extension.zip)
add_custom_command(OUTPUT ${_licvdb_addon_zips}
                   COMMAND ${PROJECT_SOURCE_DIR}/scripts/package-addon ${_licvdb_addon_dir}
                   DEPENDS ${_licvdb_addon_files} ${PROJECT_SOURCE_DIR}/scripts/package-addon
                   COMMENT "Zipping the Blender add-on (scripts/package-addon)" VERBATIM)
add_custom_target(licvdb_addon_zips ALL DEPENDS ${_licvdb_addon_zips})
# A build of only some targets (scripts/demo: --target licvdb) has no zips, or old ones: install
# makes them first where they are missing or older than the add-on's files, so that
# `cmake --install` works after any build.
install(CODE "
  set(_zips \"${_licvdb_addon_zips}\")
  set(_sources \"${_licvdb_addon_files};${PROJECT_SOURCE_DIR}/scripts/package-addon\")
  set(_stale FALSE)
  foreach(_zip IN LISTS _zips)
    if(NOT EXISTS \"\${_zip}\")
      set(_stale TRUE)
    endif()
    foreach(_src IN LISTS _sources)
      if(\"\${_src}\" IS_NEWER_THAN \"\${_zip}\")
        set(_stale TRUE)
      endif()
    endforeach()
  endforeach()
  if(_stale)
    message(STATUS \"Zipping the Blender add-on (scripts/package-addon ${_licvdb_addon_dir})\")
    execute_process(COMMAND \"${PROJECT_SOURCE_DIR}/scripts/package-addon\" \"${_licvdb_addon_dir}\"
                    RESULT_VARIABLE _rc OUTPUT_QUIET)
    if(NOT _rc EQUAL 0)
      message(FATAL_ERROR \"scripts/package-addon failed (\${_rc}): the add-on zips cannot be installed\")
    endif()
  endif()
" COMPONENT runtime)
install(FILES ${_licvdb_addon_zips} DESTINATION ${CMAKE_INSTALL_DATADIR}/licvdb/blender COMPONENT runtime)
install(FILES ${PROJECT_SOURCE_DIR}/README.md DESTINATION ${CMAKE_INSTALL_DOCDIR} COMPONENT runtime)

# --- development ----------------------------------------------------------------------------
set_target_properties(lic PROPERTIES EXPORT_NAME lic)
set_target_properties(vdbexport PROPERTIES EXPORT_NAME vdbexport)
install(TARGETS lic EXPORT licvdbLicTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR} COMPONENT development
        LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR} COMPONENT development)
install(TARGETS vdbexport EXPORT licvdbVdbexportTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR} COMPONENT development
        LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR} COMPONENT development)
install(DIRECTORY ${PROJECT_SOURCE_DIR}/lic/include/lic ${PROJECT_SOURCE_DIR}/vdbexport/include/vdbexport
        DESTINATION ${CMAKE_INSTALL_INCLUDEDIR} COMPONENT development FILES_MATCHING PATTERN "*.h")
# Two export sets: lic::lic needs only OpenVDB and TBB; lic::vdbexport (files, images, colour,
# MPI) needs more, found only when it is asked for (licvdbConfig.cmake.in).
install(EXPORT licvdbLicTargets NAMESPACE lic:: DESTINATION ${LICVDB_CMAKE_DIR} COMPONENT development)
install(EXPORT licvdbVdbexportTargets NAMESPACE lic:: DESTINATION ${LICVDB_CMAKE_DIR} COMPONENT development)
configure_package_config_file(${CMAKE_CURRENT_LIST_DIR}/licvdbConfig.cmake.in
                              ${PROJECT_BINARY_DIR}/licvdbConfig.cmake INSTALL_DESTINATION ${LICVDB_CMAKE_DIR})
write_basic_package_version_file(${PROJECT_BINARY_DIR}/licvdbConfigVersion.cmake COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/licvdbConfig.cmake ${PROJECT_BINARY_DIR}/licvdbConfigVersion.cmake
        DESTINATION ${LICVDB_CMAKE_DIR} COMPONENT development)

# --- packages (cpack -G DEB in build/) ------------------------------------------------------
set(CPACK_PACKAGE_NAME licvdb)
set(CPACK_PACKAGE_VENDOR "licvdb")
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "${PROJECT_DESCRIPTION}")
set(CPACK_PACKAGE_CONTACT "Seed 3fcdbb79 maintainers <maintainers@users.noreply.h-seed-3fcdbb79.example>")
set(CPACK_PACKAGE_INSTALL_DIRECTORY licvdb)
set(CPACK_RESOURCE_FILE_README ${PROJECT_SOURCE_DIR}/README.md)
set(CPACK_OUTPUT_FILE_PREFIX ${PROJECT_BINARY_DIR}/packages)
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_COMPONENTS_ALL runtime development)
set(CPACK_DEB_COMPONENT_INSTALL ON)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT) # licvdb_0.1.0-1_amd64.deb, licvdb-dev_0.1.0-1_amd64.deb
set(CPACK_DEBIAN_PACKAGE_RELEASE 1)
set(CPACK_DEBIAN_PACKAGE_MAINTAINER "${CPACK_PACKAGE_CONTACT}")
set(CPACK_DEBIAN_RUNTIME_PACKAGE_NAME licvdb)
set(CPACK_DEBIAN_RUNTIME_PACKAGE_SECTION graphics)
# The synopsis line is CPACK_PACKAGE_DESCRIPTION_SUMMARY; these are the bodies (CPack indents them).
set(CPACK_DEBIAN_RUNTIME_DESCRIPTION "licvdb turns a 3D vector field (CFD output, a Blender or Houdini smoke
simulation, an analytic flow) into line integral convolution volumes written
as OpenVDB grids: dense noise LIC or sparse streamlines with halos, width and
colour by scalars, looping animations. It includes a reference halo raycaster
(licvdb render) and the Blender add-on zips in /usr/share/licvdb/blender.")
# dpkg-shlibdeps finds every shared library the binaries and the modules link, with versions (libopenvdb10.0,
# libtbb12, libopenimageio2.4, libopencolorio2.1, libimath-3-1-29, libblosc1, libssl3, zlib1g,
# libopenmpi3, libvtk9.1 with VTK, libjemalloc2 with jemalloc, libstdc++6, libc6: scripts/test-install checks them). licvdb runs nothing else
# except mpirun for distributed bakes (openmpi-bin, suggested) and Blender for the add-on.
set(CPACK_DEBIAN_RUNTIME_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
if(LICVDB_MPI)
  set(CPACK_DEBIAN_RUNTIME_PACKAGE_SUGGESTS "openmpi-bin, blender")
else()
  set(CPACK_DEBIAN_RUNTIME_PACKAGE_SUGGESTS "blender")
endif()
set(CPACK_DEBIAN_DEVELOPMENT_PACKAGE_NAME licvdb-dev)
set(CPACK_DEBIAN_DEVELOPMENT_PACKAGE_SECTION libdevel)
set(CPACK_DEBIAN_DEVELOPMENT_DESCRIPTION "Development files of licvdb: headers, static libraries and the CMake
package. find_package(licvdb) gives lic::lic (fields, streamlines, LIC engines,
raycaster) and lic::vdbexport (recipes, readers, bakes to .vdb files).")
# What licvdbConfig.cmake finds: the -dev packages of the public and the (static) private
# dependencies (images and meshes need none: their modules come with the licvdb package).
set(_licvdb_dev_depends "licvdb (= ${PROJECT_VERSION}-1), libopenvdb-dev, libtbb-dev, libboost-iostreams-dev, libimath-dev, nlohmann-json3-dev, libssl-dev, zlib1g-dev, libblosc-dev, liblog4cplus-dev")
if(LICVDB_MPI)
  string(APPEND _licvdb_dev_depends ", libopenmpi-dev")
endif()
set(CPACK_DEBIAN_DEVELOPMENT_PACKAGE_DEPENDS "${_licvdb_dev_depends}")
set(CPACK_DEBIAN_DEVELOPMENT_PACKAGE_SHLIBDEPS OFF)
include(CPack)
cpack_add_component(runtime DISPLAY_NAME "licvdb tool" REQUIRED)
cpack_add_component(development DISPLAY_NAME "licvdb development files" DEPENDS runtime)
