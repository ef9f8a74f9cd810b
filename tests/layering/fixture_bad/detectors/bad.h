#pragma once
// Test fixture for tests/layering: a detectors/ header that breaks the rules. Never built.
#include <opencv2/core.hpp>
#include <vector>
