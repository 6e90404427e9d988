//! System identification from flight data: DMDc, HAVOKc, white-box baseline, NMAE, search.

