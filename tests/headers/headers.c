/* Compiles every public header as C11 (this file) and as C++ (headers.cpp). */
#include "quadkit/quadkit.h"

int main(void) { return qk_strerror(QK_OK)[0] == '\0'; }
