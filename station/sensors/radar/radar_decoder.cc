#include "station/sensors/radar/radar_decoder.h"

#include <algorithm>
#include <numeric>

namespace linecal {

std::optional<RadarModel> ParseRadarModel(std::string_view name) {
  if (name == "ars408") return RadarModel::kArs408;
  if (name == "esr") return RadarModel::kEsr;
  return std::nullopt;
}

const char* RadarSkipReasonName(RadarSkipReason reason) {
  switch (reason) {
    case RadarSkipReason::kUnknownId:
      return "unknown_id";
    case RadarSkipReason::kRemote:
      return "remote";
    case RadarSkipReason::kErrorFrame:
      return "error_frame";
    case RadarSkipReason::kShort:
      return "short";
    case RadarSkipReason::kNoCycleHeader:
      return "no_cycle_header";
    case RadarSkipReason::kDuplicate:
      return "duplicate";
    case RadarSkipReason::kUnmatchedQuality:
      return "unmatched_quality";
    case RadarSkipReason::kCount:
      break;
  }
  return "invalid";
}

int64_t RadarDecodeStats::skipped_total() const {
  return std::accumulate(skipped.begin(), skipped.end(), int64_t{0});
}

RadarDecoder::RadarDecoder(RadarModel model, const RadarConventions& conventions)
    : model_(model), conventions_(conventions) {}

void RadarDecoder::Push(const CanFrame& frame, std::vector<RadarCycle>* closed) {
  ++stats_.frames_read;
  if (frame.error) return Skip(RadarSkipReason::kErrorFrame);
  if (frame.remote) return Skip(RadarSkipReason::kRemote);
  // Both radars use 11-bit ids only; a 29-bit frame with the same number is another message.
  if (frame.extended) return Skip(RadarSkipReason::kUnknownId);
  if (model_ == RadarModel::kArs408) {
    PushArs408(frame, closed);
  } else {
    PushEsr(frame, closed);
  }
}

void RadarDecoder::Close(OpenCycle& slot, std::vector<RadarCycle>* closed) {
  if (!slot.open) return;
  slot.open = false;
  ++stats_.cycles;
  if (!slot.cycle.complete()) ++stats_.incomplete_cycles;
  stats_.detections += static_cast<int64_t>(slot.cycle.detections.size());
  closed->push_back(std::move(slot.cycle));
}

void RadarDecoder::Open(OpenCycle& slot, RadarCycle head) {
  slot.cycle = std::move(head);
  slot.index_of_id.fill(-1);
  slot.open = true;
  ++stats_.frames_decoded;
}

void RadarDecoder::PushArs408(const CanFrame& frame, std::vector<RadarCycle>* closed) {
  const std::optional<Ars408Id> which = ClassifyArs408Id(frame.id);
  if (!which) return Skip(RadarSkipReason::kUnknownId);
  const std::span<const uint8_t> payload = frame.payload();
  const bool objects = which->message == Ars408Message::kObjectStatus ||
                       which->message == Ars408Message::kObjectGeneral;
  const RadarDetectionKind kind =
      objects ? RadarDetectionKind::kObject : RadarDetectionKind::kCluster;
  OpenCycle& slot = open_[which->sensor_id][objects ? 1 : 0];

  switch (which->message) {
    case Ars408Message::kClusterStatus:
    case Ars408Message::kObjectStatus: {
      const std::optional<Ars408ListStatus> status =
          DecodeArs408ListStatus(payload, kind, conventions_);
      if (!status) return Skip(RadarSkipReason::kShort);
      Close(slot, closed);
      RadarCycle head;
      head.time = frame.time;
      head.sensor_id = which->sensor_id;
      head.kind = kind;
      head.counter = status->meas_counter;
      head.messages_expected = status->near_count + status->far_count;
      Open(slot, std::move(head));
      return;
    }
    case Ars408Message::kClusterGeneral:
    case Ars408Message::kObjectGeneral: {
      const std::optional<Ars408Target> target = DecodeArs408Target(payload, kind);
      if (!target) return Skip(RadarSkipReason::kShort);
      if (!slot.open) return Skip(RadarSkipReason::kNoCycleHeader);
      int16_t& index = slot.index_of_id[target->id];
      if (index >= 0) return Skip(RadarSkipReason::kDuplicate);
      index = static_cast<int16_t>(slot.cycle.detections.size());
      slot.cycle.detections.push_back(Ars408TargetToDetection(*target, kind, conventions_));
      ++slot.cycle.messages_received;
      ++stats_.frames_decoded;
      return;
    }
    case Ars408Message::kClusterQuality: {
      const std::optional<std::pair<int, Ars408ClusterQuality>> quality =
          DecodeArs408ClusterQuality(payload);
      if (!quality) return Skip(RadarSkipReason::kShort);
      if (!slot.open) return Skip(RadarSkipReason::kNoCycleHeader);
      const int16_t index = slot.index_of_id[quality->first];
      if (index < 0) return Skip(RadarSkipReason::kUnmatchedQuality);
      RadarDetection& detection = slot.cycle.detections[index];
      if (detection.cluster_quality) return Skip(RadarSkipReason::kDuplicate);
      detection.cluster_quality = quality->second;
      ++stats_.frames_decoded;
      return;
    }
  }
}

void RadarDecoder::PushEsr(const CanFrame& frame, std::vector<RadarCycle>* closed) {
  OpenCycle& slot = open_[0][0];
  const std::span<const uint8_t> payload = frame.payload();
  if (frame.id == esr::kStatusId) {
    const std::optional<EsrStatus> status = DecodeEsrStatus(payload);
    if (!status) return Skip(RadarSkipReason::kShort);
    Close(slot, closed);
    RadarCycle head;
    head.time = frame.time;
    head.kind = RadarDetectionKind::kTrack;
    head.counter = status->scan_index;
    head.messages_expected = esr::kTrackCount;
    Open(slot, std::move(head));
    return;
  }
  if (frame.id < esr::kFirstTrackId || frame.id >= esr::kFirstTrackId + esr::kTrackCount) {
    return Skip(RadarSkipReason::kUnknownId);
  }
  const int number = static_cast<int>(frame.id - esr::kFirstTrackId) + 1;
  const std::optional<EsrTrack> track = DecodeEsrTrack(payload, number);
  if (!track) return Skip(RadarSkipReason::kShort);
  if (!slot.open) return Skip(RadarSkipReason::kNoCycleHeader);
  int16_t& index = slot.index_of_id[number];
  if (index >= 0) return Skip(RadarSkipReason::kDuplicate);
  index = static_cast<int16_t>(slot.cycle.detections.size());
  if (track->status != esr::kNoTarget) {
    slot.cycle.detections.push_back(EsrTrackToDetection(*track, conventions_));
  }
  ++slot.cycle.messages_received;
  ++stats_.frames_decoded;
  if (slot.cycle.messages_received == esr::kTrackCount) Close(slot, closed);
}

void RadarDecoder::Finish(std::vector<RadarCycle>* closed) {
  std::vector<OpenCycle*> open;
  for (auto& lists : open_) {
    for (OpenCycle& slot : lists) {
      if (slot.open) open.push_back(&slot);
    }
  }
  std::stable_sort(open.begin(), open.end(), [](const OpenCycle* a, const OpenCycle* b) {
    return a->cycle.time < b->cycle.time;
  });
  for (OpenCycle* slot : open) Close(*slot, closed);
}

RadarDecodeResult DecodeRadarFrames(std::span<const CanFrame> frames, RadarModel model,
                                    const RadarConventions& conventions) {
  RadarDecoder decoder(model, conventions);
  RadarDecodeResult result;
  for (const CanFrame& frame : frames) decoder.Push(frame, &result.cycles);
  decoder.Finish(&result.cycles);
  result.stats = decoder.stats();
  return result;
}

}  // namespace linecal
