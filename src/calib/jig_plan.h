#pragma once
// Placeholder: the device layer replaces this with the jig plan.
