#pragma once
// Test fixture for tests/layering: a detectors/ header that breaks the rules. Never built.
#include <vector>

#include <opencv2/core.hpp>
