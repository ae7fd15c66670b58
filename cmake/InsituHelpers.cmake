# insitu_add_library(NAME SOURCES ... PUBLIC_DEPS ... PRIVATE_DEPS ...)
#   One module = one static library target insitu_<NAME>, public headers in include/insitu/<NAME>.
# insitu_add_test(MODULE NAME SOURCES ... DEPS ... LABELS ...)
#   Registers a GoogleTest binary with CTest as <MODULE>/<NAME>.

# -Wno-restrict, -Wno-maybe-uninitialized: GCC 12 false positives on std::string at -O3
# (GCC bugs 105329, 107138).
set(INSITU_WARNINGS -Wall -Wextra -Werror -Wno-error=deprecated-declarations
    $<$<CXX_COMPILER_ID:GNU>:-Wno-restrict> $<$<CXX_COMPILER_ID:GNU>:-Wno-maybe-uninitialized>)

function(insitu_add_library NAME)
  cmake_parse_arguments(ARG "" "" "SOURCES;PUBLIC_DEPS;PRIVATE_DEPS" ${ARGN})
  add_library(insitu_${NAME} STATIC ${ARG_SOURCES})
  add_library(insitu::${NAME} ALIAS insitu_${NAME})
  target_include_directories(insitu_${NAME}
    PUBLIC ${INSITU_SOURCE_DIR}/include
    PRIVATE ${INSITU_SOURCE_DIR}/src)
  target_link_libraries(insitu_${NAME} PUBLIC ${ARG_PUBLIC_DEPS} PRIVATE ${ARG_PRIVATE_DEPS})
  target_compile_options(insitu_${NAME} PRIVATE ${INSITU_WARNINGS})
endfunction()

function(insitu_add_test MODULE NAME)
  cmake_parse_arguments(ARG "" "TIMEOUT" "SOURCES;DEPS;LABELS" ${ARGN})
  set(target test_${MODULE}_${NAME})
  add_executable(${target} ${ARG_SOURCES})
  target_include_directories(${target} PRIVATE ${INSITU_SOURCE_DIR}/src ${INSITU_SOURCE_DIR}/tests)
  target_link_libraries(${target} PRIVATE ${ARG_DEPS} GTest::gtest GTest::gtest_main)
  target_compile_options(${target} PRIVATE ${INSITU_WARNINGS})
  target_compile_definitions(${target} PRIVATE INSITU_SOURCE_DIR="${INSITU_SOURCE_DIR}")
  set_target_properties(${target} PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${CMAKE_BINARY_DIR}/tests)
  add_test(NAME ${MODULE}/${NAME} COMMAND ${target})
  if(NOT ARG_LABELS)
    set(ARG_LABELS unit)
  endif()
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 300)
  endif()
  set_tests_properties(${MODULE}/${NAME} PROPERTIES LABELS "${ARG_LABELS}" TIMEOUT ${ARG_TIMEOUT}
    WORKING_DIRECTORY ${INSITU_SOURCE_DIR})
endfunction()
