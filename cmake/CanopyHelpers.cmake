# canopy_add_tool(NAME name SOURCES main.cpp LIBS lib...)
#   The executable canopy-<name>, installed to bin/.
function(canopy_add_tool)
  cmake_parse_arguments(T "" "NAME" "SOURCES;LIBS" ${ARGN})
  add_executable(canopy-${T_NAME} ${T_SOURCES})
  target_link_libraries(canopy-${T_NAME} PRIVATE ${T_LIBS} canopy_core canopy_warnings)
  install(TARGETS canopy-${T_NAME} RUNTIME DESTINATION bin)
endfunction()

# canopy_add_gtest(NAME test_x SOURCES a.cpp LIBS lib... [SANITIZE] [LABELS l...])
#   A GoogleTest executable whose cases become CTest tests. Cases whose name contains "cuda"
#   skip (GTEST_SKIP) without a GPU; CTest reports them as skipped. SANITIZE builds the test and
#   its listed SOURCES with AddressSanitizer and UBSan (only for sources compiled into the test).
function(canopy_add_gtest)
  cmake_parse_arguments(T "SANITIZE" "NAME" "SOURCES;LIBS;LABELS" ${ARGN})
  add_executable(${T_NAME} ${T_SOURCES})
  target_link_libraries(${T_NAME} PRIVATE ${T_LIBS} GTest::gtest GTest::gtest_main canopy_warnings)
  if(T_SANITIZE)
    target_compile_options(${T_NAME} PRIVATE -fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer)
    target_link_options(${T_NAME} PRIVATE -fsanitize=address,undefined)
  endif()
  target_compile_definitions(${T_NAME} PRIVATE
    CANOPY_SHARED_DIR="${CMAKE_SOURCE_DIR}/../shared"
    CANOPY_SOURCE_DIR="${CMAKE_SOURCE_DIR}"
    CANOPY_BINARY_DIR="${CMAKE_BINARY_DIR}")
  gtest_discover_tests(${T_NAME}
    TEST_PREFIX "${T_NAME}."
    DISCOVERY_TIMEOUT 60
    PROPERTIES SKIP_REGULAR_EXPRESSION "\\[  SKIPPED \\]" LABELS "${T_LABELS}")
endfunction()
