# bouncecal_write_if_changed(PATH CONTENT): writes CONTENT to PATH only when it differs from what
# is there, so that an unchanged generated header does not recompile the library. Shared by the
# generators run with `cmake -P` (embed_scene_files.cmake, embed_report_assets.cmake).
function(bouncecal_write_if_changed path content)
  if(EXISTS "${path}")
    file(READ "${path}" old)
    if(old STREQUAL content)
      return()
    endif()
  endif()
  file(WRITE "${path}" "${content}")
endfunction()
