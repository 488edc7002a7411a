"""Robot-specific controller kinds and tools, registered as plug-ins (entry points); the generic
compiler never imports them."""
