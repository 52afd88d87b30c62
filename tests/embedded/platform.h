/* platform.h - output and exit of the embedded test program: semihosting on the target
 * (startup.c), stdio on the host (embedded_test.c). */
#ifndef EMBEDDED_PLATFORM_H
#define EMBEDDED_PLATFORM_H

void platform_write(const char *text);
void platform_exit(int status);

#endif
