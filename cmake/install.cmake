# Where the program finds its files, and what `cmake --install` puts where:
#   bin/layersnet                      the program
#   share/layersnet/...                its scripts, recipes, configs and the shipped models
#                                      (cli/program_files.h looks in <program>/../share/layersnet)
#   include/layersnet/<folder>/*.h     the libraries' headers, lib/*.a the libraries
#   lib/cmake/layersnet/               layersnetConfig.cmake: find_package(layersnet) gives
#                                      layersnet::layersnet (all libraries) and one target per folder
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

# --- Program files --------------------------------------------------------------------------
# Paths relative to the source root; folders whole, except what only the repository needs.
set(LAYERSNET_PROGRAM_FILES generate configs dataset/check_dlayers_h5.py scripts/outfit_from_h5.py
    models/medium/model.h5 models/large/model.h5)

# The build tree mirrors the install layout with links to the sources, so a build directory
# anywhere (not only build/ inside the sources) finds the files the way an install does, and
# edits to the sources need no re-configure.
foreach(path IN LISTS LAYERSNET_PROGRAM_FILES)
  set(link ${CMAKE_BINARY_DIR}/share/layersnet/${path})
  get_filename_component(parent ${link} DIRECTORY)
  file(MAKE_DIRECTORY ${parent})
  if(IS_SYMLINK ${link})
    file(REMOVE ${link})
  endif()
  file(CREATE_LINK ${CMAKE_SOURCE_DIR}/${path} ${link} SYMBOLIC)
endforeach()

install(TARGETS layersnet RUNTIME DESTINATION bin)
install(DIRECTORY generate/ DESTINATION share/layersnet/generate
        PATTERN predictability EXCLUDE PATTERN __pycache__ EXCLUDE)
install(DIRECTORY configs/ DESTINATION share/layersnet/configs)
install(FILES dataset/check_dlayers_h5.py DESTINATION share/layersnet/dataset)
install(PROGRAMS scripts/outfit_from_h5.py DESTINATION share/layersnet/scripts)
install(FILES models/medium/model.h5 DESTINATION share/layersnet/models/medium)
install(FILES models/large/model.h5 DESTINATION share/layersnet/models/large)

# --- Libraries and their package config -----------------------------------------------------
set(LAYERSNET_LIBRARIES)
foreach(dir autodiff dataset model losses run train eval bench simulate inspect)
  if(NOT TARGET layersnet_${dir})
    continue()
  endif()
  set(lib layersnet_${dir})
  list(APPEND LAYERSNET_LIBRARIES ${lib})
  # The folders add the source root as a plain include path; an install has the headers
  # under include/layersnet instead.
  get_target_property(dirs ${lib} INTERFACE_INCLUDE_DIRECTORIES)
  set(exported)
  foreach(d IN LISTS dirs)
    if(d STREQUAL CMAKE_SOURCE_DIR)
      list(APPEND exported "$<BUILD_INTERFACE:${d}>")
    else()
      list(APPEND exported "${d}")
    endif()
  endforeach()
  set_target_properties(${lib} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${exported}" EXPORT_NAME ${dir})
  target_include_directories(${lib} INTERFACE $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}/layersnet>)
  # Eigen's fixed-size types change layout with the vector width: a program using these headers
  # must compile for the same CPU features as the libraries.
  if(LAYERSNET_NATIVE)
    target_compile_options(${lib} INTERFACE $<INSTALL_INTERFACE:-march=native>)
  endif()
  install(DIRECTORY ${dir}/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/layersnet/${dir} FILES_MATCHING PATTERN "*.h")
endforeach()

add_library(layersnet_libraries INTERFACE)
target_link_libraries(layersnet_libraries INTERFACE ${LAYERSNET_LIBRARIES})
set_target_properties(layersnet_libraries PROPERTIES EXPORT_NAME layersnet)
# Static libraries carry their private links into the export (as link-only): the warning flags'
# target goes along, and a consumer needs the private dependencies found again.
set_target_properties(layersnet_warnings PROPERTIES EXPORT_NAME warnings)
install(TARGETS ${LAYERSNET_LIBRARIES} layersnet_libraries layersnet_warnings EXPORT layersnetTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR})
install(EXPORT layersnetTargets NAMESPACE layersnet:: DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/layersnet)

# train/ links MPI privately when it is installed; the consumer then needs it too.
set(LAYERSNET_FIND_MPI OFF)
if(TARGET layersnet_train)
  get_target_property(train_links layersnet_train LINK_LIBRARIES)
  if("MPI::MPI_C" IN_LIST train_links)
    set(LAYERSNET_FIND_MPI ON)
  endif()
endif()
set(LAYERSNET_PROGRAM_FILES_INSTALL_DIR share/layersnet)
configure_package_config_file(cmake/layersnetConfig.cmake.in ${CMAKE_BINARY_DIR}/generated/layersnetConfig.cmake
                              INSTALL_DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/layersnet
                              PATH_VARS LAYERSNET_PROGRAM_FILES_INSTALL_DIR)
write_basic_package_version_file(${CMAKE_BINARY_DIR}/generated/layersnetConfigVersion.cmake
                                 COMPATIBILITY SameMinorVersion)
install(FILES ${CMAKE_BINARY_DIR}/generated/layersnetConfig.cmake
              ${CMAKE_BINARY_DIR}/generated/layersnetConfigVersion.cmake
        DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/layersnet)
