"""``--technique auto``: per light, the registered technique and setting predicted to meet a time
budget or an error target, from features of the stage (:mod:`wsoft.auto.features`) and a model
learnt from sweep rows (:mod:`wsoft.auto.model`); :mod:`wsoft.auto.choose` picks. This package
sits above the techniques and the pipeline: it reads the techniques' registry and registers
``auto`` with the frame graph's builder (:data:`wsoft.pipeline.build.CHOOSERS`); neither imports it
(``wsoft.render``, ``wsoft.compare``, ``wsoft.plan`` and the command line import it first)."""


def _register() -> None:
    from wsoft.auto.choose import auto_technique
    from wsoft.pipeline.build import CHOOSERS

    CHOOSERS["auto"] = auto_technique


_register()
