# canopy_chaar: the .chaar format (reader, writer, CPU decoder and encoder). No OpenVDB, so it
# compiles fast and can be sanitized and fuzzed. canopy_chaar_cuda: the GPU decoder (CUDA builds).
add_library(canopy_chaar STATIC
  ${CMAKE_CURRENT_LIST_DIR}/chaar.cpp
  ${CMAKE_CURRENT_LIST_DIR}/haar_encode.cpp)
target_include_directories(canopy_chaar PUBLIC ${CMAKE_CURRENT_LIST_DIR}/..)
target_link_libraries(canopy_chaar PUBLIC canopy_core PRIVATE canopy_warnings)

if(CANOPY_HAS_CUDA)
  add_library(canopy_chaar_cuda STATIC ${CMAKE_CURRENT_LIST_DIR}/haar_cuda.cu)
  target_link_libraries(canopy_chaar_cuda PUBLIC canopy_chaar PRIVATE canopy_warnings)
  # Device lambdas for the decode kernel.
  target_compile_options(canopy_chaar_cuda PRIVATE $<$<COMPILE_LANGUAGE:CUDA>:--extended-lambda>)
endif()
