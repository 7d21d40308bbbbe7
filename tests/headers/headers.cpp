// Compiles every public header as C++.
#include "quadkit/quadkit.h"

int main() { return qk_strerror(QK_OK)[0] == '\0'; }
