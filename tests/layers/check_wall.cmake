# One wall between layers (docs/DESIGN.md, "Layers"): a file that includes HIDDEN with the include
# roots of INCLUDES (the layer's and those below, joined by "|") must fail to compile because that
# header is not found, while one that includes VISIBLE, the layer's own, compiles. Run by ctest:
#   cmake -DCXX=... -DINCLUDES=a|b -DVISIBLE=engine/x.h -DHIDDEN=io/y.h -DWORK=dir -P check_wall.cmake
foreach(var CXX INCLUDES VISIBLE HIDDEN WORK)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "check_wall.cmake: ${var} is not set")
  endif()
endforeach()
string(REPLACE "|" ";" roots "${INCLUDES}")
set(flags -std=c++20 -fsyntax-only)
foreach(root IN LISTS roots)
  if(NOT root MATCHES "^/usr(/local)?/include$")  # the compiler's own: as -I they would reorder its search
    list(APPEND flags -I${root})
  endif()
endforeach()
file(MAKE_DIRECTORY ${WORK})

# HEADER's include compiled with the layer's roots; sets <prefix>_code and <prefix>_errors.
function(compile_include prefix header)
  string(MAKE_C_IDENTIFIER ${header} name)
  set(source ${WORK}/${name}.cpp)
  file(WRITE ${source} "#include \"${header}\"\n")
  execute_process(COMMAND ${CMAKE_COMMAND} -E env LC_ALL=C ${CXX} ${flags} ${source} RESULT_VARIABLE code
                  ERROR_VARIABLE errors OUTPUT_QUIET)
  set(${prefix}_code ${code} PARENT_SCOPE)
  set(${prefix}_errors "${errors}" PARENT_SCOPE)
endfunction()

compile_include(visible ${VISIBLE})
if(NOT visible_code EQUAL 0)
  message(FATAL_ERROR "the layer's own header ${VISIBLE} does not compile with its roots:\n${visible_errors}")
endif()
compile_include(hidden ${HIDDEN})
if(hidden_code EQUAL 0)
  message(FATAL_ERROR "${HIDDEN}, of a layer above, compiles with the roots ${INCLUDES}: the wall is open")
endif()
string(FIND "${hidden_errors}" "${HIDDEN}: No such file" gcc_says)      # GCC
string(FIND "${hidden_errors}" "'${HIDDEN}' file not found" clang_says)  # clang
if(gcc_says EQUAL -1 AND clang_says EQUAL -1)
  message(FATAL_ERROR "${HIDDEN} failed to compile, but not as a missing file:\n${hidden_errors}")
endif()
message(STATUS "${HIDDEN} is not found with the roots ${INCLUDES}, ${VISIBLE} is")
