# Toolchain file: bare-metal Arm Cortex-M4F (hard-float ABI), GNU Arm Embedded (Debian package
# gcc-arm-none-eabi, with libnewlib-arm-none-eabi for newlib-nano).  With it the top-level
# project builds the board images (firmware/port/mps2-an386); tests are off in a cross build:
#
#   cmake -S . -B build/m4 -DCMAKE_TOOLCHAIN_FILE=cmake/arm-none-eabi.cmake
#   cmake --build build/m4 -j2
#
# -ffp-contract=off on every target: fused multiply-adds would change the float bits
# (the library is bit-identical to the float32 reference only without them).
set(CMAKE_SYSTEM_NAME Generic)
set(CMAKE_SYSTEM_PROCESSOR arm)

set(CMAKE_C_COMPILER arm-none-eabi-gcc)
set(CMAKE_ASM_COMPILER arm-none-eabi-gcc)
find_program(CMAKE_OBJCOPY arm-none-eabi-objcopy)
find_program(CMAKE_SIZE arm-none-eabi-size)
find_program(NTE_ARM_NM arm-none-eabi-nm)

# A bare-metal compiler cannot link a test program without a linker script.
set(CMAKE_TRY_COMPILE_TARGET_TYPE STATIC_LIBRARY)

# -fno-math-errno: sqrtf becomes the FPU's VSQRT in place (correctly rounded either way, so
# no float changes) instead of a call to newlib's wrapper that sets errno, which nothing here
# reads: 350 B of the 32 KiB flash (the Setting frame's handling needed them) and fewer cycles.
set(NTE_M4_FLAGS "-mcpu=cortex-m4 -mthumb -mfpu=fpv4-sp-d16 -mfloat-abi=hard -ffp-contract=off -fno-math-errno")
# -flto: the images are optimised whole at link time, one partition (-flto-partition=one):
# 1 712 B less flash than compiled object by object (32 712 B then), and 2–4 % fewer cycles a
# step, with the same bits (the self-test's output is unchanged).  Each function keeps the
# options it was compiled with (-O2 on the step path, -Os where a target asks for it).
# -fstack-usage and -fcallgraph-info=su: per-function stack and the call graph.  With -flto
# the code is generated at link time, so the link writes them too, with -save-temps=obj:
# bin/<image>.elf.ltrans0.ltrans.ci beside the image, from which figures.py computes the
# worst-case stack (with the .ci of any object compiled without -flto).
set(CMAKE_C_FLAGS_INIT
    "${NTE_M4_FLAGS} -flto -ffunction-sections -fdata-sections -fstack-usage -fcallgraph-info=su")
# -O2 (not CMake's -O3 -DNDEBUG): the size, stack and cycle figures are of this build
set(CMAKE_C_FLAGS_RELEASE "-O2" CACHE STRING "C flags of the Release board build")
set(CMAKE_ASM_FLAGS_INIT "${NTE_M4_FLAGS}")
set(CMAKE_EXE_LINKER_FLAGS_INIT
    "${NTE_M4_FLAGS} -flto -flto-partition=one -fstack-usage -fcallgraph-info=su \
-save-temps=obj --specs=nano.specs -nostartfiles -Wl,--gc-sections")
# newlib-nano's libc, libm and libgcc last on every link line (sqrtf; the compiler's helpers)
set(CMAKE_C_STANDARD_LIBRARIES_INIT "-Wl,--start-group -lm -lc_nano -lgcc -Wl,--end-group")
if(NOT CMAKE_BUILD_TYPE)
  set(CMAKE_BUILD_TYPE Release CACHE STRING "Build type (the board image: Release, -O2)")
endif()

# Search the host for programs only; libraries and headers come from the toolchain.
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
