"""Local view cells: the template bank and its matchers (stage 1 of the data flow)."""

from torchratslam.local_view.view import (
    FeatureView,
    LocalView,
    TemplateBank,
    TemplateMatcher,
    preprocess,
)

__all__ = ["FeatureView", "LocalView", "TemplateBank", "TemplateMatcher", "preprocess"]
