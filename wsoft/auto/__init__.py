"""``--technique auto``: per light, the registered technique and setting predicted to meet a time
budget or an error target, from features of the stage (:mod:`wsoft.auto.features`) and a model
learnt from sweep rows (:mod:`wsoft.auto.model`); :mod:`wsoft.auto.choose` picks. This package
sits above the techniques: it reads their registry, no technique imports it."""
