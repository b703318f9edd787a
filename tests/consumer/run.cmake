# The install test: installs the build tree into a fresh prefix, configures and builds tests/consumer against it
# with find_package(scanpress), and runs the consumer on a golden container.
# cmake -DBUILD_DIR=... -DWORK_DIR=... -DSOURCE_DIR=... -DGENERATOR=... -DCXX_COMPILER=... -DBUILD_TYPE=...
#       -DCONTAINER=... -DEXPECTED_VERTICES=... -P run.cmake
function(run)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE code OUTPUT_VARIABLE out ERROR_VARIABLE out)
  string(JOIN " " cmd ${ARGN})
  message("$ ${cmd}\n${out}")
  if(NOT code EQUAL 0)
    message(FATAL_ERROR "failed (${code})")
  endif()
endfunction()

set(prefix ${WORK_DIR}/prefix)
set(build ${WORK_DIR}/build)
file(REMOVE_RECURSE ${WORK_DIR})
run(${CMAKE_COMMAND} --install ${BUILD_DIR} --prefix ${prefix})
foreach(f include/engine/container/container.h bin/scanpress)
  if(NOT EXISTS ${prefix}/${f})
    message(FATAL_ERROR "not installed: ${prefix}/${f}")
  endif()
endforeach()
# Only the prefix: no package registry, so that nothing but the installed package can be found.
run(${CMAKE_COMMAND} -S ${SOURCE_DIR} -B ${build} -G "${GENERATOR}" -DCMAKE_CXX_COMPILER=${CXX_COMPILER}
    -DCMAKE_BUILD_TYPE=${BUILD_TYPE} -DCMAKE_PREFIX_PATH=${prefix} -DCMAKE_FIND_USE_PACKAGE_REGISTRY=OFF)
run(${CMAKE_COMMAND} --build ${build})
run(${build}/consumer ${CONTAINER} ${EXPECTED_VERTICES})
file(REMOVE_RECURSE ${WORK_DIR})
