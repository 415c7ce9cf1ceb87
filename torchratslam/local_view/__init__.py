"""Local view cells: the template bank and its matchers (stage 1 of the data flow)."""

from torchratslam.local_view.bank import TemplateBank
from torchratslam.local_view.matcher import TemplateMatcher
from torchratslam.local_view.preprocessing import preprocess
from torchratslam.local_view.view import FeatureView, LocalView

__all__ = ["FeatureView", "LocalView", "TemplateBank", "TemplateMatcher", "preprocess"]
