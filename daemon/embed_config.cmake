# Writes a C++ source whose builtin_config_text() returns the contents of INPUT.
file(READ ${INPUT} text)
file(WRITE ${OUTPUT} "// Generated from config/laserline.yaml; do not edit.\n"
  "#include \"daemon/config.hpp\"\n"
  "namespace laserline::daemon {\n"
  "const char* builtin_config_text() {\n  return R\"laserline_yaml(${text})laserline_yaml\";\n}\n"
  "}  // namespace laserline::daemon\n")
