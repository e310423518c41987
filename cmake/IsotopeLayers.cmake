# The layers' walls (docs/DESIGN.md, "Layers"): engine (no I/O) <- io <- the faces (tools/, dist/,
# bench/, python/). Every include names its layer ("engine/core/parallel.h", "io/store/..."), and a
# target sees only the roots of its own layer and of those below it, so an include that goes up
# (engine naming io, io naming tools) does not compile, whatever a review misses.
#
# A layer's root is a folder of the build tree that holds one symbolic link, named as the layer, to
# the layer's sources: with it on a target's include path, "LAYER/..." resolves, and no other
# folder of the repository does.
function(isotope_layer_root out layer)
  set(root ${PROJECT_BINARY_DIR}/layers/${layer})
  set(target "")
  if(IS_SYMLINK ${root}/${layer})
    file(READ_SYMLINK ${root}/${layer} target)
  endif()
  if(NOT target STREQUAL "${PROJECT_SOURCE_DIR}/${layer}")  # none yet, or another checkout's
    file(REMOVE ${root}/${layer})
    file(MAKE_DIRECTORY ${root})
    file(CREATE_LINK ${PROJECT_SOURCE_DIR}/${layer} ${root}/${layer} SYMBOLIC)
  endif()
  set(${out} ${root} PARENT_SCOPE)
endfunction()
