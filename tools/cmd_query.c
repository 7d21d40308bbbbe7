/* Query subcommands (placeholder until the query module lands). */
#include "cli.h"

static int not_yet(char **argv) {
  cli_error(argv[0], "not implemented yet");
  return CLI_INTERNAL;
}
int cmd_knn(int argc, char **argv) {
  (void)argc;
  return not_yet(argv);
}
int cmd_range(int argc, char **argv) {
  (void)argc;
  return not_yet(argv);
}
int cmd_radius(int argc, char **argv) {
  (void)argc;
  return not_yet(argv);
}
int cmd_locate(int argc, char **argv) {
  (void)argc;
  return not_yet(argv);
}
int cmd_collide(int argc, char **argv) {
  (void)argc;
  return not_yet(argv);
}
int cmd_raycast(int argc, char **argv) {
  (void)argc;
  return not_yet(argv);
}
int cmd_geo(int argc, char **argv) {
  (void)argc;
  return not_yet(argv);
}
