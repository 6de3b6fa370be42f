#pragma once
// Constants of the ONI file format shared by the writer and the structural check
// (docs/ONI.md). All integers are little-endian.
#include <cstddef>
#include <cstdint>

namespace tessera::drivers::oni::format {

constexpr std::size_t kFileHeaderBytes = 24;        // "NI10", version, largest timestamp, node id
constexpr std::size_t kRecordHeaderBytes = 28;      // magic, type, node, sizes, undo offset
constexpr std::uint32_t kRecordMagic = 0x0052494E;  // "NIR\0"

// Record types.
constexpr std::uint32_t kIntProperty = 0x03;
constexpr std::uint32_t kGeneralProperty = 0x06;
constexpr std::uint32_t kNodeRemoved = 0x07;
constexpr std::uint32_t kNodeDataBegin = 0x08;
constexpr std::uint32_t kNodeStateReady = 0x09;
constexpr std::uint32_t kNewData = 0x0A;
constexpr std::uint32_t kEnd = 0x0B;
constexpr std::uint32_t kNodeAdded = 0x0D;
constexpr std::uint32_t kSeekTable = 0x0E;

// Node types of a node-added record.
constexpr std::uint32_t kDepthNode = 2;
constexpr std::uint32_t kImageNode = 3;

}  // namespace tessera::drivers::oni::format
