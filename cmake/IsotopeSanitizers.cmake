# ISOTOPE_SANITIZE=address,undefined or thread: applied to every target in the tree.
if(ISOTOPE_SANITIZE)
  set(_san "-fsanitize=${ISOTOPE_SANITIZE}")
  if(ISOTOPE_SANITIZE MATCHES "undefined")
    string(APPEND _san " -fno-sanitize-recover=undefined")
  endif()
  separate_arguments(_san_list UNIX_COMMAND "${_san}")
  # No -g of its own: the build type's flags choose the debug information (CI asks
  # for line tables, -g1, which is all a sanitizer's report needs to name file and line; a -g here
  # would come after them and override them, for a build a quarter slower).
  add_compile_options(${_san_list} -fno-omit-frame-pointer)
  if(ISOTOPE_SANITIZE MATCHES "thread")
    add_compile_definitions(ISOTOPE_STD_THREADS)  # see engine/core/parallel.h
  endif()
  add_link_options(${_san_list})
endif()
