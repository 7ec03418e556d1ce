# Shared build settings and the helpers every module uses.

if(TWINFORGE_SANITIZE)
  add_compile_options(-fsanitize=address,undefined -fno-omit-frame-pointer)
  add_link_options(-fsanitize=address,undefined)
endif()

get_filename_component(TWINFORGE_SOURCE_DIR ${CMAKE_CURRENT_LIST_DIR}/.. ABSOLUTE)

# twinforge_module(<name> SOURCES ... DEPS ...): the library of one src/<name> module.
function(twinforge_module name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS" ${ARGN})
  add_library(twinforge_${name} STATIC ${ARG_SOURCES})
  target_include_directories(twinforge_${name} PUBLIC ${TWINFORGE_SOURCE_DIR}/src)
  target_link_libraries(twinforge_${name} PUBLIC ${ARG_DEPS})
  target_compile_options(twinforge_${name} PRIVATE -Wall -Wextra)
  target_compile_definitions(twinforge_${name}
    PUBLIC TWINFORGE_ASSETS_DIR="${TWINFORGE_SOURCE_DIR}/assets")
endfunction()

# twinforge_test(<file_test.cpp> DEPS ... [LABELS ...] [COST seconds]): one gtest file beside its
# code. COST, for a file with a long test: about its longest test's seconds on one core. ctest -j
# starts tests in falling cost, so a fresh build's long tests run first instead of leaving one core
# idle while a long one started last finishes (the CI machine has no timings of earlier runs).
function(twinforge_test file)
  if(NOT TWINFORGE_BUILD_TESTS)
    return()
  endif()
  cmake_parse_arguments(ARG "" "COST" "DEPS;LABELS" ${ARGN})
  set(cost)
  if(ARG_COST)
    set(cost COST ${ARG_COST})
  endif()
  get_filename_component(stem ${file} NAME_WE)
  get_filename_component(module ${CMAKE_CURRENT_SOURCE_DIR} NAME)
  set(target ${module}_${stem})
  add_executable(${target} ${file})
  target_link_libraries(${target} PRIVATE ${ARG_DEPS} GTest::gtest GTest::gtest_main)
  target_compile_definitions(${target} PRIVATE
    TWINFORGE_TEST_DATA_DIR="${TWINFORGE_SOURCE_DIR}/tests/fixtures")
  include(GoogleTest)
  # One OpenMP thread per test, as the CLI's start-up pins its main thread (learn::PinMathThreads):
  # ctest runs tests side by side, and Open3D's TSDF integration in a scan test spun on every core.
  # libgomp reads the variable when it loads, so it is set here, not by the test.
  set(env ENVIRONMENT OMP_NUM_THREADS=1)
  if(ARG_LABELS)
    # Discovery writes a list property unquoted (LABELS a b: b is read as another property), so
    # a file with labels of its own has its tests listed from the source at configure time.
    gtest_add_tests(TARGET ${target} SOURCES ${file} TEST_LIST tests)
    set_tests_properties(${tests} PROPERTIES LABELS "${module};${ARG_LABELS}" ${cost} ${env})
  else()
    gtest_discover_tests(${target} PROPERTIES LABELS "${module}" ${cost} ${env}
                       DISCOVERY_TIMEOUT 60)
  endif()
endfunction()
