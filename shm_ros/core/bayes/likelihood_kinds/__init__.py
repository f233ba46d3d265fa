"""The likelihoods of updating, one file each; see :mod:`.base` for the extension point."""
