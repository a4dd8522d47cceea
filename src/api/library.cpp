// The shared library is cdm_internal linked whole; this file only gives the
// target a translation unit of its own.
#include "cdm/cdm.h"
