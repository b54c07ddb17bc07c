# cmake -DBINARY=path -P check_front_binary.cmake: fails when the binary's dynamic section names a library of the gRPC
# stack, protobuf or OpenVDB (readelf from binutils).
execute_process(COMMAND readelf -d ${BINARY} OUTPUT_VARIABLE dynamic RESULT_VARIABLE rc)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "readelf -d ${BINARY} failed (${rc})")
endif()
string(REGEX MATCHALL "\\[[^]]*(grpc|protobuf|absl|openvdb|ssl)[^]]*\\]" forbidden "${dynamic}")
if(forbidden)
  message(FATAL_ERROR "${BINARY} links ${forbidden}: the front binary must start without them")
endif()
string(REGEX MATCHALL "NEEDED" needed "${dynamic}")
list(LENGTH needed count)
message(STATUS "${BINARY}: ${count} NEEDED libraries, none of gRPC, protobuf, abseil, OpenSSL or OpenVDB")
