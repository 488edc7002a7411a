"""Reports: versioned JSON first, then HTML rendered from that JSON alone, and graph exports."""
