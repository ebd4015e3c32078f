/* tools/output_error.h: the error line of the tools that read a simulator's output (check, measure):
 * "TOOL: FILE:LINE: problem" on stderr and exit status 1. The tool defines TOOL_NAME before including
 * this, and sets output_name and output_line as it reads. */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

static const char *output_name = "-";
static long long output_line;

static void die(const char *fmt, ...)
{
    va_list ap;
    fprintf(stderr, TOOL_NAME ": %s:%lld: ", output_name, output_line);
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    fputc('\n', stderr);
    exit(1);
}
