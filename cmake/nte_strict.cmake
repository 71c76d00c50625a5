# The project's one set of compile rules, for every C target (library, CAN layer, node, ports,
# host programs, board images, tests), with gcc or clang, host or cross:
#
#   C99 without extensions, and the INTERFACE target `nte_strict`, which carries
#   -Wall -Wextra -Werror -pedantic -Wconversion -Wdouble-promotion -Wshadow -Wfloat-equal
#   -Wundef and -ffp-contract=off (fused multiply-adds would change the float bits: the library
#   is bit-identical to the reference only without them).
#
# Every target links it: target_link_libraries(T PRIVATE nte_strict).  Included by the
# top-level CMakeLists.txt and by firmware/CMakeLists.txt (so a project that only adds
# firmware/ as a subdirectory gets the same rules).
include_guard(GLOBAL)

set(CMAKE_C_STANDARD 99)
set(CMAKE_C_STANDARD_REQUIRED ON)
set(CMAKE_C_EXTENSIONS OFF)

if(NOT TARGET nte_strict)
  add_library(nte_strict INTERFACE)
  target_compile_features(nte_strict INTERFACE c_std_99)
  set(NTE_STRICT_FLAGS -Wall -Wextra -Werror -pedantic -Wconversion -Wdouble-promotion
      -Wshadow -Wfloat-equal -Wundef -ffp-contract=off)
  target_compile_options(nte_strict INTERFACE "$<$<COMPILE_LANGUAGE:C>:${NTE_STRICT_FLAGS}>")
endif()

# Per-function stack use (.su files beside the objects) where the compiler has it: the stack
# figures of the library and the board come from it.
include(CheckCCompilerFlag)
check_c_compiler_flag(-fstack-usage NTE_HAVE_STACK_USAGE)
set(NTE_STACK_USAGE_FLAG "")
if(NTE_HAVE_STACK_USAGE)
  set(NTE_STACK_USAGE_FLAG -fstack-usage)
endif()
