"""Camera calibration from a planar target seen in several views (Zhang's method)."""
