# The browser viewer (viewer/): three.js and the viewer's script bundled by esbuild, both from npm
# (the viewer's package lock; the dependency install runs `npm ci`), then embedded in the isotope
# binary as the viewer assets (ViewerAsset). Defines isotope_viewer_sources(OUT_VAR) for tools/.
set(ISOTOPE_VIEWER_DIR ${PROJECT_SOURCE_DIR}/viewer)
find_program(ISOTOPE_NODE node)
if(NOT ISOTOPE_NODE OR NOT EXISTS ${ISOTOPE_VIEWER_DIR}/node_modules/esbuild/package.json
   OR NOT EXISTS ${ISOTOPE_VIEWER_DIR}/node_modules/three/package.json)
  message(FATAL_ERROR "The viewer needs Node.js and its npm packages: run scripts/install-deps.sh "
                      "(or: npm ci --prefix viewer)")
endif()

function(isotope_viewer_sources out_var)
  set(out ${CMAKE_CURRENT_BINARY_DIR}/viewer)
  file(GLOB src CONFIGURE_DEPENDS ${ISOTOPE_VIEWER_DIR}/src/*)
  add_custom_command(
    OUTPUT ${out}/index.html ${out}/viewer.js ${out}/viewer.css
    COMMAND ${ISOTOPE_NODE} ${ISOTOPE_VIEWER_DIR}/build.mjs ${out}
    DEPENDS ${src} ${ISOTOPE_VIEWER_DIR}/build.mjs ${ISOTOPE_VIEWER_DIR}/package-lock.json
    COMMENT "Building the viewer (viewer/build.mjs: esbuild)"
    VERBATIM)
  set(VIEWER_INDEX_HTML ${out}/index.html)
  set(VIEWER_CSS ${out}/viewer.css)
  set(VIEWER_JS ${out}/viewer.js)
  configure_file(${PROJECT_SOURCE_DIR}/tools/serve/viewer_assets.cpp.in ${out}/viewer_assets.cpp @ONLY)
  set_source_files_properties(${out}/viewer_assets.cpp PROPERTIES
    OBJECT_DEPENDS "${out}/viewer.js;${VIEWER_INDEX_HTML};${VIEWER_CSS}")
  set(${out_var} ${out}/viewer_assets.cpp ${out}/index.html ${out}/viewer.js ${out}/viewer.css PARENT_SCOPE)
endfunction()
