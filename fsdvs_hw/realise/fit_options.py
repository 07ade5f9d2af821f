"""A hardware fit's options: one pydantic model, validated once at the fit's entry, rules included.

Every hardware fit declares its keyword options as a :class:`FitOptions` model (``options.py`` in
its folder, held by :attr:`~fsdvs_hw.realise.registry.RealisationSpec.options`): each option's
type, default, range and unit (:func:`fsdvs_hw.schema.field`), and the rules no single option's
range can state, of two kinds:

* rules between options (a fixed ``pixel_weight`` of 0 with ``gain = 'free'``):
  :meth:`FitOptions.option_problems`;
* rules on the target kernel (``fit_size`` at least the kernel's size): :meth:`FitOptions.target_problems`.

Both run in one model validator when the validation context holds the target (``{"target":
kernel}``), that is when the whole set of options and the kernel are known: a design file's
``[realisations.<name>]`` table once the design's target is loaded (:mod:`fsdvs_hw.design`), and a
fit's arguments at its entry (:func:`fsdvs_hw.validation.check_fit_arguments` builds the options
object, coerces the target with :meth:`FitOptions.target_of` and checks both with
:meth:`FitOptions.with_target`); the fit then works from that object (its :attr:`FitOptions.target`
is the coerced kernel). A table checked one key at a time (a sweep axis) meets only the ranges.
Both paths run the same rules and a broken rule reads the same in both
(:func:`raise_option_problems`): ``key '<option>' = <value>: <why>; allowed: <what the option allows>``.
"""

from __future__ import annotations

from typing import Any, ClassVar, NamedTuple, Self

from pydantic import PrivateAttr, ValidationError, ValidationInfo, model_validator
from pydantic_core import InitErrorDetails, PydanticCustomError

from ..errors import InputError
from ..kernels import Kernel, as_kernel
from ..schema import StrictModel, problems, validate

__all__ = ["FitOptions", "OptionProblem", "raise_option_problems"]


class OptionProblem(NamedTuple):
    """One broken rule: the option it is reported on, that option's value, and why (a few words)."""

    option: str
    value: Any
    why: str


def raise_option_problems(model: type[StrictModel], found: list[OptionProblem]) -> None:
    """Raise every problem in ``found`` as one :class:`pydantic.ValidationError` located at its option.

    Raised inside a validator of ``model``, pydantic reports each at ``<table>.<option>``, so
    :func:`fsdvs_hw.schema.problems` writes it like a range error of that option (with the option's
    allowed values). Nothing happens when ``found`` is empty.
    """
    if found:
        details = [
            InitErrorDetails(type=PydanticCustomError("option_rule", p.why), loc=(p.option,), input=p.value)
            for p in found
        ]
        raise ValidationError.from_exception_data(model.__name__, details)


class FitOptions(StrictModel):
    """Base of a hardware fit's options model: fields, rules between options, rules on the target.

    A subclass declares one field per keyword option of its fit, and its rules by overriding
    :meth:`option_problems` (between options) and :meth:`target_problems` (on the target).
    """

    #: Name of the target kernel the fit coerces (:func:`fsdvs_hw.kernels.as_kernel`'s ``name``).
    kernel_name: ClassVar[str] = "kernel"

    _target: Kernel | None = PrivateAttr(default=None)

    def option_problems(self) -> list[OptionProblem]:
        """The rules between options this set of options breaks; none here."""
        return []

    def target_problems(self, target: Kernel) -> list[OptionProblem]:
        """The options the target kernel rules out (at the pitch :meth:`target_of` gives it); none here."""
        return []

    @model_validator(mode="after")
    def _follows_the_rules(self, info: ValidationInfo) -> Self:
        """The rules between options and on the target, when the validation context holds the target."""
        target = (info.context or {}).get("target")
        if target is not None:
            found = self.option_problems()
            raise_option_problems(type(self), found + self.target_problems(self.target_of(target)))
        return self

    def target_of(self, kernel: Any) -> Kernel:
        """The kernel the fit works on: ``kernel`` coerced, at the ``pitch_m`` option when it is set.

        Raises
        ------
        InputError
            ``kernel`` is not a kernel (:func:`~fsdvs_hw.kernels.as_kernel` says why).
        """
        return as_kernel(kernel, name=self.kernel_name, pitch_m=getattr(self, "pitch_m", None), repitch=True)

    def with_target(self, kernel: Any) -> Self:
        """These options checked against each other (:meth:`option_problems`, before ``kernel`` is
        looked at) and against the target ``kernel`` (:meth:`target_problems`), holding it.

        Raises
        ------
        InputError
            A broken rule between options, ``kernel`` not a kernel, or every option the target rules
            out, one line each.
        """
        self.refuse(self.option_problems())  # a bad kernel does not hide a broken rule between options
        target = self.target_of(kernel)
        given = {name: getattr(self, name) for name in self.model_fields_set}
        checked = validate(type(self), given, context={"target": target})
        assert isinstance(checked, type(self))
        checked._target = target
        return checked

    def refuse(self, found: list[OptionProblem]) -> None:
        """Raise the problems ``found`` outside a validation, in the words a validation uses.

        Raises
        ------
        InputError
            Each problem, one line each (nothing is raised when ``found`` is empty).
        """
        try:
            raise_option_problems(type(self), found)
        except ValidationError as exc:
            lines = problems(exc, type(self))
            raise InputError(
                lines[0] if len(lines) == 1 else f"{len(lines)} problems:\n  " + "\n  ".join(lines)
            ) from None

    @property
    def target(self) -> Kernel:
        """The coerced target kernel (set by :meth:`with_target`)."""
        if self._target is None:
            raise InputError(f"{type(self).__name__}: no target kernel yet (use with_target)")
        return self._target
