# What building a rosidl interface package against the ROS 2 wheels of a venv needs beyond an
# ordinary ament_cmake build. interfaces/build_interfaces.sh includes it into each package's
# project (CMAKE_PROJECT_INCLUDE); a colcon build in the pip-only venv passes it the same way
# (docs/ros.md). The package's CMakeLists stays what a ROS installation builds. Both steps run
# once the CMakeLists has been read (cmake_language(DEFER)), when the package's targets and every
# imported target exist; target properties are read when the build files are generated.
cmake_minimum_required(VERSION 3.19)

function(_wheel_prefix_fixups)
  # 1. The wheels' exported targets name the include folders of the machine that built them
  #    (e.g. a manylinux Python under /opt/python); drop the folders that do not exist here.
  get_directory_property(_imported IMPORTED_TARGETS)
  foreach(_target IN LISTS _imported)
    get_target_property(_dirs ${_target} INTERFACE_INCLUDE_DIRECTORIES)
    if(_dirs)
      set(_kept "")
      foreach(_dir IN LISTS _dirs)
        if(_dir MATCHES "^\\$<" OR EXISTS "${_dir}")
          list(APPEND _kept "${_dir}")
        endif()
      endforeach()
      set_target_properties(${_target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${_kept}")
    endif()
  endforeach()
  # 2. The typesupport dispatch libraries open the library of the typesupport an RMW asks for by
  #    its file name at run time (dlopen), which only LD_LIBRARY_PATH would find. Linked to them,
  #    the implementations load with the dispatch library, through its RPATH, and dlopen returns
  #    those.
  foreach(_lang c cpp)
    set(_dispatch ${PROJECT_NAME}__rosidl_typesupport_${_lang})
    foreach(_impl fastrtps introspection)
      set(_impl_target ${PROJECT_NAME}__rosidl_typesupport_${_impl}_${_lang})
      if(TARGET ${_dispatch} AND TARGET ${_impl_target})
        target_link_options(${_dispatch} PRIVATE "LINKER:--no-as-needed")
        target_link_libraries(${_dispatch} PRIVATE ${_impl_target})
      endif()
    endforeach()
  endforeach()
endfunction()

cmake_language(DEFER CALL _wheel_prefix_fixups)
