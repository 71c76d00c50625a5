# Forwarder: CMake resolves a relative CMAKE_TOOLCHAIN_FILE against the build tree, then the
# source tree (this directory), so `-DCMAKE_TOOLCHAIN_FILE=cmake/arm-none-eabi.cmake` from the
# repository root lands here.  The toolchain itself is the repository's cmake/arm-none-eabi.cmake.
include(${CMAKE_CURRENT_LIST_DIR}/../../../../cmake/arm-none-eabi.cmake)
