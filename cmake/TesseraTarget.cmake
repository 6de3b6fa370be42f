# One place for the compile settings every tessera target shares.
function(tessera_target_settings target)
  target_compile_features(${target} PUBLIC cxx_std_20)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wconversion -Wshadow)
  if(TESSERA_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
  if(CMAKE_UNITY_BUILD)
    # Merged sources: a member of one file's type that uses another file's anonymous-namespace
    # type is reported, though each file alone is clean.
    target_compile_options(${target} PRIVATE -Wno-subobject-linkage)
  endif()
  if(TESSERA_SANITIZE)
    # vptr is left out: oneTBB's flow-graph headers downcast task memory before constructing
    # the task, which the vptr check reports inside TBB on every graph run.
    target_compile_options(${target} PRIVATE -fsanitize=address,undefined -fno-sanitize=vptr
                                             -fno-omit-frame-pointer -fno-sanitize-recover=undefined)
    target_link_options(${target} PUBLIC -fsanitize=address,undefined)
  endif()
endfunction()
