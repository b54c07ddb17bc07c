// Keeps distband_test_support non-empty before any oracle exists.
