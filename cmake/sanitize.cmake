# Sanitizer build of everything the project compiles (library, CAN layer, node, port, host
# programs, every C test), selected by -DNTE_SANITIZE=ON.  Use it without editing any
# CMakeLists through CMake's project hook:
#   CC=clang cmake -S . -B build/asan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DNTE_SANITIZE=ON \
#         -DCMAKE_PROJECT_INCLUDE=$PWD/cmake/sanitize.cmake
#   cmake --build build/asan -j2 && ctest --test-dir build/asan
# or include(cmake/sanitize.cmake) right after project() in the top-level CMakeLists.txt.
# Any finding aborts the test that hit it (-fno-sanitize-recover=all), so ctest reports it as a
# failure.  gcc also works (it has no float-cast-overflow in "undefined"; it is listed anyway).
option(NTE_SANITIZE "Build with AddressSanitizer + UndefinedBehaviorSanitizer" OFF)
if(NTE_SANITIZE AND NOT NTE_SANITIZE_APPLIED)
  set(NTE_SANITIZE_APPLIED ON)
  set(NTE_SANITIZE_FLAGS -fsanitize=address,undefined,float-cast-overflow
      -fno-sanitize-recover=all -fno-omit-frame-pointer -g)
  add_compile_options(${NTE_SANITIZE_FLAGS})
  add_link_options(${NTE_SANITIZE_FLAGS})
  # Leaks are findings too; abort on the first error of any kind.
  set(NTE_SANITIZE_ENV
      "ASAN_OPTIONS=detect_leaks=1:abort_on_error=1:halt_on_error=1:detect_stack_use_after_return=1"
      "UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1")
  message(STATUS "NTE_SANITIZE: ${NTE_SANITIZE_FLAGS}")
endif()
