# Installation (`cmake --install BUILD --prefix P`, `make install PREFIX=P`): the hrad binary,
# libhrad.a and libhrad.so.MAJOR.MINOR.PATCH, the public headers, hrad.pc for pkg-config, the
# CMake package (find_package(hrad): hrad::hrad, the shared library, and hrad::hrad_static) and
# the man page hrad(1). Every installed file is relocatable: hrad.pc and the CMake package find
# the prefix from where they lie.
include(CMakePackageConfigHelpers)

install(TARGETS hrad RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
install(TARGETS hradlib hrad_shared EXPORT hradTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
        LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
        INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
install(FILES ${HR_PUBLIC_HEADERS} DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
install(FILES ${CMAKE_SOURCE_DIR}/docs/hrad.1 DESTINATION ${CMAKE_INSTALL_MANDIR}/man1)

# pkg-config: the prefix relative to the .pc file's own directory.
file(RELATIVE_PATH HR_PC_TO_PREFIX "/${CMAKE_INSTALL_LIBDIR}/pkgconfig" "/")
string(REGEX REPLACE "/$" "" HR_PC_TO_PREFIX "${HR_PC_TO_PREFIX}")
configure_file(${CMAKE_SOURCE_DIR}/cmake/hrad.pc.in ${CMAKE_BINARY_DIR}/hrad.pc @ONLY)
install(FILES ${CMAKE_BINARY_DIR}/hrad.pc DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig)

set(HR_CMAKE_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/hrad)
install(EXPORT hradTargets NAMESPACE hrad:: DESTINATION ${HR_CMAKE_DIR})
configure_package_config_file(${CMAKE_SOURCE_DIR}/cmake/hradConfig.cmake.in
                              ${CMAKE_BINARY_DIR}/hradConfig.cmake
                              INSTALL_DESTINATION ${HR_CMAKE_DIR})
# 0.x: a minor version may change the API, so only the same MAJOR.MINOR is compatible.
write_basic_package_version_file(${CMAKE_BINARY_DIR}/hradConfigVersion.cmake
                                 COMPATIBILITY SameMinorVersion)
install(FILES ${CMAKE_BINARY_DIR}/hradConfig.cmake ${CMAKE_BINARY_DIR}/hradConfigVersion.cmake
        DESTINATION ${HR_CMAKE_DIR})
