/* fail() of the model API (glue.h): the one way a model, the instance core and the glue put a
 * message that names a problem into msg. Its own file, so that the model tests link a model
 * without the instance core. */
#include <stdarg.h>
#include <stdio.h>

#include "glue.h"

int fail(char *msg, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, MSG_MAX, fmt, ap);
    va_end(ap);
    return 1;
}
