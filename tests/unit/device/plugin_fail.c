/* A plugin whose init fails: cdm_effect_load_plugin must unload it. */
#define CDM_EXPERIMENTAL /* cdm_effect_def lives in the experimental block */
#include "cdm/cdm.h"

int cdm_plugin_init(int (*register_fn)(const cdm_effect_def *));
int cdm_plugin_init(int (*register_fn)(const cdm_effect_def *)) {
    (void)register_fn;
    return CDM_ERR_INVALID_ARG;
}
