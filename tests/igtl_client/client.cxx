// A client on the reference OpenIGTLink library (Debian libopenigtlink-dev, 1.11, protocol v2).
//
// Connects to HOST PORT, sends a TRANSFORM "ScalpelToReference" (translation 1 2 3),
// GET_CAPABIL, GET_STATUS and GET_POLYDATA, then GET_STATUS "ClientDone"; prints one
// line per message it receives, with the library's own CRC check, until the reply to
// "ClientDone" (the endpoint answers a client's messages in order) or the end of the stream.
//
//   MSG <type> <device> crc=ok|bad [details]
//
// Build: tests/igtl_client/build.sh OUT (g++ with the package's include and library paths).

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "igtlCapabilityMessage.h"
#include "igtlClientSocket.h"
#include "igtlMessageHeader.h"
#include "igtlPolyDataMessage.h"
#include "igtlStatusMessage.h"
#include "igtlTransformMessage.h"

static const char* kAttrNames[] = {"SCALAR", "VECTOR", "NORMAL", "TENSOR", "RGBA"};

template <class M>
static bool receive(igtl::ClientSocket* sock, igtl::MessageHeader* head, M* msg) {
  msg->SetMessageHeader(head);
  msg->AllocatePack();
  if (sock->Receive(msg->GetPackBodyPointer(), msg->GetPackBodySize()) != msg->GetPackBodySize()) {
    return false;
  }
  return (msg->Unpack(1) & igtl::MessageHeader::UNPACK_BODY) != 0;  // 1: check the CRC
}

static void print_polydata(igtl::PolyDataMessage* pd) {
  int npoints = pd->GetPoints() ? pd->GetPoints()->GetNumberOfPoints() : 0;
  int npolys = pd->GetPolygons() ? (int)pd->GetPolygons()->GetNumberOfCells() : 0;
  std::printf(" points=%d polygons=%d attributes=", npoints, npolys);
  for (int i = 0; i < pd->GetNumberOfAttributes(); i++) {
    igtl::PolyDataAttribute* att = pd->GetAttribute(i);
    int kind = att->GetType() & 0x0F;
    float first[16] = {0};
    if (att->GetSize() > 0) {
      att->GetNthData(0, first);
    }
    std::printf("%s%s:%s%s:%u:%u:%g,%g,%g", i ? ";" : "", att->GetName(), (att->GetType() & 0x10) ? "CELL_" : "POINT_",
                kind <= 4 ? kAttrNames[kind] : "?", att->GetSize(), att->GetNumberOfComponents(), first[0], first[1],
                first[2]);
  }
}

static bool handle(igtl::ClientSocket* sock, igtl::MessageHeader* head) {
  std::string type = head->GetDeviceType();
  std::string name = head->GetDeviceName();
  bool ok = false;
  std::printf("MSG %s %s", type.c_str(), name.empty() ? "-" : name.c_str());
  if (type == "STATUS") {
    igtl::StatusMessage::Pointer m = igtl::StatusMessage::New();
    ok = receive(sock, head, m.GetPointer());
    std::printf(" crc=%s code=%d subcode=%lld error=%s text=%s\n", ok ? "ok" : "bad", m->GetCode(),
                (long long)m->GetSubCode(), m->GetErrorName(), m->GetStatusString());
    return name != "ClientDone";
  }
  if (type == "CAPABILITY") {
    igtl::CapabilityMessage::Pointer m = igtl::CapabilityMessage::New();
    ok = receive(sock, head, m.GetPointer());
    std::printf(" crc=%s types=", ok ? "ok" : "bad");
    for (int i = 0; i < m->GetNumberOfTypes(); i++) {
      std::printf("%s%s", i ? "," : "", m->GetType(i));
    }
  } else if (type == "TRANSFORM") {
    igtl::TransformMessage::Pointer m = igtl::TransformMessage::New();
    ok = receive(sock, head, m.GetPointer());
    igtl::Matrix4x4 mat;
    m->GetMatrix(mat);
    std::printf(" crc=%s translation=%g,%g,%g", ok ? "ok" : "bad", mat[0][3], mat[1][3], mat[2][3]);
  } else if (type == "POLYDATA") {
    igtl::PolyDataMessage::Pointer m = igtl::PolyDataMessage::New();
    ok = receive(sock, head, m.GetPointer());
    std::printf(" crc=%s", ok ? "ok" : "bad");
    print_polydata(m.GetPointer());
  } else {
    sock->Skip(head->GetBodySizeToRead(), 0);
    std::printf(" crc=skipped");
  }
  std::printf("\n");
  return true;
}

static void send_header_only(igtl::ClientSocket* sock, igtl::MessageBase* m, const char* name) {
  m->SetDeviceName(name);
  m->Pack();
  sock->Send(m->GetPackPointer(), m->GetPackSize());
}

int main(int argc, char* argv[]) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: %s HOST PORT\n", argv[0]);
    return 2;
  }
  igtl::ClientSocket::Pointer sock = igtl::ClientSocket::New();
  if (sock->ConnectToServer(argv[1], std::atoi(argv[2])) != 0) {
    std::fprintf(stderr, "cannot connect to %s:%s\n", argv[1], argv[2]);
    return 1;
  }
  sock->SetReceiveTimeout(20000);  // ms: a bound on a stuck endpoint, never reached when it answers

  igtl::TransformMessage::Pointer tr = igtl::TransformMessage::New();
  igtl::Matrix4x4 mat;
  igtl::IdentityMatrix(mat);
  mat[0][3] = 1.0f;
  mat[1][3] = 2.0f;
  mat[2][3] = 3.0f;
  tr->SetMatrix(mat);
  tr->SetDeviceName("ScalpelToReference");
  tr->Pack();
  sock->Send(tr->GetPackPointer(), tr->GetPackSize());
  igtl::GetCapabilityMessage::Pointer cap = igtl::GetCapabilityMessage::New();
  send_header_only(sock, cap.GetPointer(), "");
  igtl::GetStatusMessage::Pointer st = igtl::GetStatusMessage::New();
  send_header_only(sock, st.GetPointer(), "");
  igtl::GetPolyDataMessage::Pointer gp = igtl::GetPolyDataMessage::New();
  send_header_only(sock, gp.GetPointer(), "CutkitTissue");
  igtl::GetStatusMessage::Pointer done = igtl::GetStatusMessage::New();
  send_header_only(sock, done.GetPointer(), "ClientDone");

  igtl::MessageHeader::Pointer head = igtl::MessageHeader::New();
  while (true) {
    head->InitPack();
    int r = sock->Receive(head->GetPackPointer(), head->GetPackSize());
    if (r != head->GetPackSize()) {
      std::printf("END\n");
      break;
    }
    head->Unpack();
    if (!handle(sock.GetPointer(), head.GetPointer())) {
      std::printf("DONE\n");
      break;
    }
    std::fflush(stdout);
  }
  sock->CloseSocket();
  return 0;
}
