# ISOTOPE_SANITIZE=address,undefined or thread: applied to every target in the tree.
if(ISOTOPE_SANITIZE)
  set(_san "-fsanitize=${ISOTOPE_SANITIZE}")
  if(ISOTOPE_SANITIZE MATCHES "undefined")
    string(APPEND _san " -fno-sanitize-recover=undefined")
  endif()
  separate_arguments(_san_list UNIX_COMMAND "${_san}")
  # Line tables (-g1) are all a sanitizer's report needs to name file and line. A build type with
  # debug information chooses its own (CI asks for -g1): a -g here would come after its flags and
  # override them, and compiling the heaviest files took a quarter longer with it. Other build
  # types (Release, the default) get -g1, so that their reports name file and line too.
  add_compile_options(${_san_list} -fno-omit-frame-pointer $<$<NOT:$<CONFIG:Debug,RelWithDebInfo>>:-g1>)
  if(ISOTOPE_SANITIZE MATCHES "thread")
    add_compile_definitions(ISOTOPE_STD_THREADS)  # parallel_for on std::threads: oneTBB is not instrumented
  endif()
  add_link_options(${_san_list})
endif()
