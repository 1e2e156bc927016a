"""Control laws of the report: the flatness-based controller and the formation laws."""
