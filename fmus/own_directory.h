/* The directory of the library that includes this (the FMU's loader, fmu_loader.c; the FMI 3.0 layer,
 * fmi3_layer.c): where the libraries beside it are found. */
#ifndef PMSM_OWN_DIRECTORY_H
#define PMSM_OWN_DIRECTORY_H

#include <dlfcn.h>
#include <stdio.h>
#include <string.h>

/* the directory of this library (with a trailing '/'), or "" */
static void own_directory(char* out, size_t size)
{
    Dl_info self;
    out[0] = '\0';
    if (!dladdr((void*)&own_directory, &self) || self.dli_fname == NULL) return;
    snprintf(out, size, "%s", self.dli_fname);
    char* slash = strrchr(out, '/');
    if (slash) slash[1] = '\0';
    else out[0] = '\0';
}

#endif
