# The three.js files viewer.html inlines (src/viewer.c), embedded in the library at build time so
# that an installed or copied hrad writes a working viewer without the source tree. They come from
# node_modules/three (npm, pinned in package.json; scripts/setup.sh installs it). Sets
# HR_VIEWER_ASSETS_C, the generated C file, which defines hr_viewer_assets[] (src/output.h).
set(HR_THREE_DIR ${CMAKE_SOURCE_DIR}/node_modules/three)
set(HR_VIEWER_ASSET_FILES
    build/three.module.min.js
    examples/jsm/utils/BufferGeometryUtils.js
    examples/jsm/controls/OrbitControls.js
    examples/jsm/loaders/GLTFLoader.js
    LICENSE)
set(HR_VIEWER_ASSETS_C ${CMAKE_BINARY_DIR}/viewer_assets.c)
set(_found ON)
set(_inputs)
foreach(f ${HR_VIEWER_ASSET_FILES})
  if(NOT EXISTS ${HR_THREE_DIR}/${f})
    set(_found OFF)
  endif()
  list(APPEND _inputs ${HR_THREE_DIR}/${f})
endforeach()
if(_found)
  add_custom_command(OUTPUT ${HR_VIEWER_ASSETS_C}
    COMMAND ${CMAKE_COMMAND} -DDIR=${HR_THREE_DIR} "-DFILES=${HR_VIEWER_ASSET_FILES}"
            -DOUT=${HR_VIEWER_ASSETS_C} -P ${CMAKE_SOURCE_DIR}/cmake/embed.cmake
    DEPENDS ${_inputs} ${CMAKE_SOURCE_DIR}/cmake/embed.cmake
    COMMENT "Embedding three.js for viewer.html"
    VERBATIM)
else()
  message(WARNING "${HR_THREE_DIR}: three.js not found (run scripts/setup.sh): hrad will write "
                  "viewer.html only when HRAD_THREE_DIR names a node_modules/three directory")
  execute_process(COMMAND ${CMAKE_COMMAND} -DOUT=${HR_VIEWER_ASSETS_C} "-DFILES="
                          -P ${CMAKE_SOURCE_DIR}/cmake/embed.cmake)
endif()
